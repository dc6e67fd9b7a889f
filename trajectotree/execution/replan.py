"""Replanning during execution (executor grasp-replan): the `Replanner`, a system of the execution
Diagram, plans again from the measured state when what the closed loop measures says the plan no longer
holds, and swaps the new plan in; one Diagram and one Simulator run the whole execution.

The Replanner keeps the plan in effect in abstract state (a `Replanning`: the PlanInEffect, the nodes
still to check, the friction and mass the plan assumes, the replans so far) and puts the PlanInEffect
on its output port `plan`, which feeds the `plan` input of every system that follows the plan (the grasp
controller, the landing reflex, the contact monitor and the friction estimator: execution.in_effect), so
that a swap reaches them all at once. Its periodic unrestricted update (at controller.rate_hz) looks,
at the first update at or after each node of the plan in effect (where every finger holds the object
at rest, the moment a plan may start from), at the closed loop's estimates and monitor through its
input ports: when the friction estimate has fallen `friction_drop` below the plan's, the mass estimate
is `mass_change` off the plan's, the object is `theta_error` or `position_error` off its planned pose,
or a finger the plan holds with is out of contact, the planner runs from the measured state
(trajectotree.planning.start) to the same goal, with the estimated friction and mass.

Honest timing: the planner runs inside the update, so the simulated world stands still while it
computes, and its wall-clock compute time is measured; the plan swapped in at the update's time
t_switch holds the measured state (with the old plan's forces at the node) until t_switch + that time
in simulated time, as the hand would hold while a real planner ran. The planner solves the new plan's
first segment before the others (keyframes.solve_first_segment_first) and the new plan takes effect
once that segment's measured compute time has passed; each later segment begins no earlier than its
own measured readiness (the last attempt of it and of its two neighbours, whose joint retries could
replace it), so the hand holds at a node while a segment is not ready. The search gets
controller.replan.search_deadline_s, and the first segment must be ready within
first_segment_deadline_s of the measured state. A start the planner refuses, a search without a plan
(in time or at all) or a first segment that fails (or is not solved in time) is recorded with its typed
reason (results.ReplanOutcome, the refusal) and the old plan resumes after the same hold; a plan whose
later segment failed is executed up to that segment and planned again from there. The run ends at the
end of the plan in effect (and config.sim.settle_time of hold): a swap moves it
(executor.ExecutorSystems.advance_to_end).

Against the phase-by-phase runs before (one Simulator per phase, its state copied across): a node is
checked at the first control update at or after it (within one control period, 2 ms at 500 Hz), and a
swap does not re-run every system's initialization update, so replanned runs differ slightly from those.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import EventStatus, LeafSystem

from trajectotree.config import Config, SceneConfig
from trajectotree.execution.in_effect import PLAN_PORT, PlanInEffect, plan_in_effect
from trajectotree.execution.reference import Reference, reference_from_arrays
from trajectotree.planning.planners import plan as make_plan
from trajectotree.planning.start import StartRefused
from trajectotree.refusal import NoPlan, OnGrids, Refusal, RefusalKind
from trajectotree.results import PlanResult, ReplanEvent, ReplanOutcome, ReplanReason
from trajectotree.scene.plant import Scene
from trajectotree.start import StartState

# s, over which the reference moves from the old plan's node to the measured state while the planner runs
HOLD_RAMP = 0.05


@dataclass(frozen=True)
class Phase:
    """The plan being executed: where the closed loop looks at its state (absolute simulated times of
    the nodes it arrives at, before the goal) and, for a plan that ends short of its goal, when it must
    plan again (the last node's arrival, or when the failure was known if later)."""

    checks: tuple[float, ...]  # s
    ends_short_s: float | None = None  # s

    def due(self, t: float) -> tuple[bool, ReplanReason | None, Phase]:
        """Whether a check falls at or before `t` (the update at or after a node), the reason it forces
        (PLAN_ENDS_SHORT where the plan ends short, else None) and the phase after it."""
        checked = any(c <= t + 1e-9 for c in self.checks)
        short = self.ends_short_s is not None and self.ends_short_s <= t + 1e-9
        rest = Phase(tuple(c for c in self.checks if c > t + 1e-9), None if short else self.ends_short_s)
        return checked or short, ReplanReason.PLAN_ENDS_SHORT if short else None, rest

    def after(self, t: float, delay: float = 0.0) -> Phase:
        """The checks after `t`, `delay` later (the old plan resuming after a hold)."""
        end = None if self.ends_short_s is None else self.ends_short_s + delay
        return Phase(tuple(c + delay for c in self.checks if c > t + 1e-9), end)


def node_times(plan: PlanResult, start_s: float) -> np.ndarray:
    """The absolute times of `plan`'s nodes (its segments span knots_per_segment knots)."""
    m = plan.config.cito.knots_per_segment
    return start_s + np.asarray(plan.trajectory.t)[::m] - plan.trajectory.t[0]


def replan_reason(values: dict, assumed: SceneConfig, config: Config) -> ReplanReason | None:
    """Why the plan in effect, which assumes the scene `assumed` (its friction and mass), no longer
    holds, from the closed loop's `values` now (mu_estimate, mass_estimate, tracking_error, in_contact;
    None: it holds)."""
    rules = config.controller.replan
    if values["mu_estimate"][0] < assumed.mu - rules.friction_drop:
        return ReplanReason.FRICTION
    if abs(values["mass_estimate"][0] - assumed.box_mass) > rules.mass_change * assumed.box_mass:
        return ReplanReason.MASS
    error = values["tracking_error"]
    if abs(error[2]) > rules.theta_error or np.hypot(error[0], error[1]) > rules.position_error:
        return ReplanReason.TRACKING
    if np.any(values["in_contact"] < 0.5):
        return ReplanReason.CONTACT_LOST
    return None


@dataclass(frozen=True, eq=False)
class Replanning:
    """The Replanner's state: the `plan` in effect, the `phase` (its nodes still to check), the scene
    it `assumed` (the last new plan's estimates of friction and mass) and the `events` (each replan)."""

    plan: PlanInEffect
    phase: Phase
    assumed: SceneConfig
    events: tuple[ReplanEvent, ...] = ()

    def __deepcopy__(self, memo) -> Replanning:
        # Immutable: Drake copies abstract state at each unrestricted update; a copy shares it.
        return self


class Replanner(LeafSystem):
    """Replans `plan` (a PlanResult: its goal; executed with `config`) during its execution (module doc).
    Input ports: `box_state` (6: x m, y m, theta rad and their rates, the object's planar joint),
    `hand_state` (4F: the hand's [q rad; v rad/s]), `mu_estimate` (1), `mass_estimate` (1, kg),
    `tracking_error` (3: m, m, rad) and `in_contact` (F, 1/0), the closed loop's outputs of those names.
    Output port `plan` (abstract: the PlanInEffect). `initial`: the plan in effect at the start (its
    reference `plan`'s); the later segments of a new plan on `segment_workers` local processes (None: as
    planning.planners.plan takes them)."""

    def __init__(
        self, plan: PlanResult, config: Config, scene: Scene, initial: PlanInEffect, segment_workers: int | None
    ):
        super().__init__()
        self._plan, self._config, self._scene, self._segment_workers = plan, config, scene, segment_workers
        self._num_joints = scene.num_hand_joints
        start = Phase(tuple(node_times(plan, 0.0)[1:-1]))
        self._state = self.DeclareAbstractState(AbstractValue.Make(Replanning(initial, start, plan.config.scene)))
        self.box_state_port = self.DeclareVectorInputPort("box_state", 6)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * scene.num_hand_joints)
        self._estimate_ports = {
            name: self.DeclareVectorInputPort(name, size)
            for name, size in (("mu_estimate", 1), ("mass_estimate", 1), ("tracking_error", 3))
        }
        self._estimate_ports["in_contact"] = self.DeclareVectorInputPort("in_contact", scene.num_fingers)
        self.plan_port = self.DeclareAbstractOutputPort(
            PLAN_PORT, lambda: AbstractValue.Make(initial), self.CalcPlan, {self.abstract_state_ticket(self._state)}
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / config.controller.rate_hz, 0.0, self._Update)

    def replanning(self, context) -> Replanning:
        """The state in this system's `context`."""
        return context.get_abstract_state(self._state).get_value()

    def end_s(self, context) -> float:
        """s, when the run ends: the plan in effect's end, then config.sim.settle_time of hold."""
        return self.replanning(context).plan.reference.duration + self._config.sim.settle_time

    def CalcPlan(self, context, output):
        output.set_value(self.replanning(context).plan)

    def _Update(self, context, state):
        now = self.replanning(context)
        t = context.get_time()
        checked, forced, rest = now.phase.due(t)
        if not checked or len(now.events) >= self._config.controller.replan.max_replans:
            return EventStatus.DidNothing()
        values = {name: port.Eval(context) for name, port in self._estimate_ports.items()}
        reason = replan_reason(values, now.assumed, self._config) or forced
        after = dataclasses.replace(now, phase=rest) if reason is None else self.replanned(context, now, reason)
        state.get_mutable_abstract_state(self._state).set_value(after)
        return EventStatus.Succeeded()

    def measured_start(self, context) -> StartState:
        box, hand = self.box_state_port.Eval(context), self.hand_state_port.Eval(context)
        return StartState(object_pose=tuple(box[:3]), q=tuple(hand[: self._num_joints]), object_velocity=tuple(box[3:]))

    def replanned(self, context, now: Replanning, reason: ReplanReason) -> Replanning:
        """The state after planning again at this update for `reason` (the world stands still meanwhile)."""
        t_switch, scene, start = context.get_time(), self._scene, self.measured_start(context)
        mu, mass = (float(self._estimate_ports[name].Eval(context)[0]) for name in ("mu_estimate", "mass_estimate"))
        event, new = replan(self._plan, self._config, start, t_switch, reason, mu, mass, scene, self._segment_workers)
        reference, assumed = now.plan.reference, now.assumed
        if event.planned:
            m = new.config.cito.knots_per_segment
            usable = next((k for k, r in enumerate(event.segment_ready_s) if not np.isfinite(r)), None)
            arrays = new.trajectory.arrays()
            if usable is not None:  # the segments before the failed one
                arrays = {name: values[: usable * m + 1] for name, values in arrays.items()}
            ready = [r - event.latency_s for r in event.segment_ready_s]
            new_reference, arrivals = scheduled(reference_from_arrays(arrays, scene), m, ready)
            reference = spliced(reference, t_switch, start, scene, new_reference, event.takes_effect_s)
            arrivals = event.takes_effect_s + arrivals
            if usable is None:
                phase = Phase(tuple(arrivals[1:-1]))
            else:  # planned again at the last node reached, once the failure is known
                known = t_switch + event.compute_s
                phase = Phase(tuple(arrivals[1:-1]), max(arrivals[-1], known))
            assumed = new.config.scene
        else:  # the hand held while the planner ran: the old plan resumes that much later
            reference = delayed(reference, t_switch, event.latency_s)
            phase = now.phase.after(t_switch, event.latency_s)
        swapped = plan_in_effect(reference, self._config, scene, assumed.mu, now.plan.version + 1)
        return Replanning(swapped, phase, assumed, now.events + (event,))


def scheduled(new: Reference, knots_per_segment: int, ready: list[float]) -> tuple[Reference, np.ndarray]:
    """`new` (segments of knots_per_segment knots) as executed when its segment k may begin no earlier
    than ready[k] s after segment 0 begins (ready[0] = 0, inf: never): where a segment is not ready at
    its node the reference holds that node (a static grasp: zero velocities), and it ends at the first
    segment that never is. Also the times the nodes are reached (node 0 at 0)."""
    m = knots_per_segment
    t = new.t - new.t[0]
    index, times, arrivals = [0], [0.0], [0.0]
    for k, start in enumerate(ready):
        if not np.isfinite(start) or (k + 1) * m > len(t) - 1:
            break
        begin = max(arrivals[-1], start)
        if begin > arrivals[-1] + 1e-9:  # the node held until the segment is ready
            index.append(k * m)
            times.append(begin)
        for i in range(k * m + 1, (k + 1) * m + 1):
            index.append(i)
            times.append(begin + t[i] - t[k * m])
        arrivals.append(times[-1])
    xdot = _xdot(new)
    held = Reference(
        t=np.asarray(times),
        x=new.x[index],
        q=new.q[index],
        p_WF=new.p_WF[index],
        v_WF=new.v_WF[index],
        f_W=new.f_W[index],
        xdot=xdot[index],
        p_WC=None if new.p_WC is None else new.p_WC[index],
    )
    return held, np.asarray(arrivals)


def delayed(reference: Reference, t_switch: float, delay: float) -> Reference:
    """`reference` holding its state at `t_switch` (a node: at rest) for `delay` s, then going on as before."""
    if delay <= 1e-9:
        return reference
    before, after = reference.t < t_switch - 1e-9, reference.t > t_switch + 1e-9
    at = [t_switch, t_switch + delay]

    def cut(values: np.ndarray, zero: bool = False) -> np.ndarray:
        flat = values.reshape(len(reference.t), -1)
        node = np.array([np.interp(t_switch, reference.t, flat[:, j]) for j in range(flat.shape[1])])
        node = np.zeros_like(node) if zero else node
        held = np.stack([node, node]).reshape((2,) + values.shape[1:])
        return np.concatenate([values[before], held, values[after]])

    return Reference(
        t=np.concatenate([reference.t[before], at, reference.t[after] + delay]),
        x=cut(reference.x),
        q=cut(reference.q),
        p_WF=cut(reference.p_WF),
        v_WF=cut(reference.v_WF, zero=True),
        f_W=cut(reference.f_W),
        xdot=cut(_xdot(reference), zero=True),
    )


def spliced(
    old: Reference, t_switch: float, start: StartState, scene: Scene, new: Reference, t_new: float
) -> Reference:
    """`old` up to `t_switch`, then a hold of the measured `start` (its fingertips, the old plan's
    forces at t_switch) until `t_new`, then `new` shifted to begin at `t_new`."""
    keep = old.t < t_switch - 1e-9
    at = old.object_pose_at([t_switch])[0]
    f_at = old.forces_at([t_switch])[0]
    p_WF = scene.fingertip_positions(np.asarray(start.q))
    q0 = np.asarray(start.q)
    hold_t = [t_switch, t_switch + min(HOLD_RAMP, 0.5 * (t_new - t_switch))]
    hold_x = [at, np.asarray(start.object_pose)]
    hold_q = [np.interp(t_switch, old.t, old.q[:, j]) for j in range(old.q.shape[1])]
    F = old.p_WF.shape[1]
    p_WF_at = np.stack([np.interp(t_switch, old.t, old.p_WF[:, i, a]) for i in range(F) for a in (0, 1)])
    t = np.concatenate([old.t[keep], hold_t, t_new + new.t])
    x = np.concatenate([old.x[keep], hold_x, new.x])
    q = np.concatenate([old.q[keep], [hold_q, q0], new.q])
    p = np.concatenate([old.p_WF[keep], [p_WF_at.reshape(F, 2), p_WF], new.p_WF])
    v = np.concatenate([old.v_WF[keep], np.zeros((2, F, 2)), new.v_WF])
    f = np.concatenate([old.f_W[keep], [f_at, f_at], new.f_W])
    xdot = np.concatenate([_xdot(old)[keep], np.zeros((2, 3)), _xdot(new)])
    return Reference(t=t, x=x, q=q, p_WF=p, v_WF=v, f_W=f, xdot=xdot)


def _xdot(reference: Reference) -> np.ndarray:
    return reference.xdot if reference.xdot is not None else np.gradient(reference.x, reference.t, axis=0)


def replan(
    plan: PlanResult,
    config: Config,
    start: StartState,
    t_switch: float,
    reason: ReplanReason,
    mu: float,
    mass: float,
    scene: Scene,
    segment_workers: int | None,
) -> tuple[ReplanEvent, PlanResult | None]:
    """Plans from the measured `start` to `plan`'s goal with the estimated friction and mass (the
    search within controller.replan.search_deadline_s, the first segment first); the event and the new plan."""
    rules = config.controller.replan
    assumed = dataclasses.replace(
        config,
        scene=dataclasses.replace(
            config.scene,
            mu=mu,
            box_mass=mass,
            object_inertia=None if config.scene.object_inertia is None else config.scene.inertia_zz(mass),
        ),
        search=dataclasses.replace(config.search, time_budget_s=rules.search_deadline_s),
    )
    first_first = config.cito.formulation == "keyframes"
    t0 = time.perf_counter()
    try:
        new = make_plan(
            goal=plan.goal if plan.config.goal.theta is None else plan.config.goal,  # with its position
            start=start,
            config=assumed,
            scene=scene,  # the executed object's geometry, for the start's contacts (plan() rebuilds it from the start)
            segment_workers=segment_workers,
            first_segment_first=first_first,
            first_segment_deadline_s=rules.first_segment_deadline_s if first_first else None,
        )
    except StartRefused as refused:  # the old plan goes on
        latency = time.perf_counter() - t0
        event = ReplanEvent(
            t_switch, reason, mu, mass, latency, t_switch + latency, ReplanOutcome.START_REFUSED, str(refused)
        )
        return dataclasses.replace(event, refusal=refused.refusal, compute_s=latency), None
    total = time.perf_counter() - t0
    searched = new.contact_plan
    if not searched.success:
        late = new.search_time_s >= rules.search_deadline_s or out_of_time(searched.refusal)
        outcome = ReplanOutcome.SEARCH_DEADLINE if late else ReplanOutcome.NO_PLAN
        event = ReplanEvent(t_switch, reason, mu, mass, total, t_switch + total, outcome, new.status)
        return dataclasses.replace(event, refusal=searched.refusal, compute_s=total, search_s=new.search_time_s), None
    ready = new.segment_ready_s if first_first else (total,) * (len(searched.nodes) - 1)
    # the joint formulation is one program: none of a failed one is executed
    if new.trajectory is None or not np.isfinite(ready[0]) or not (first_first or new.success):
        # ran out of time: segment 0's attempts came back no sooner than its deadline
        late = first_first and ready[0] >= rules.first_segment_deadline_s
        outcome = ReplanOutcome.FIRST_SEGMENT_LATE if late else ReplanOutcome.FIRST_SEGMENT_FAILED
        event = ReplanEvent(t_switch, reason, mu, mass, total, t_switch + total, outcome, new.status)
        return dataclasses.replace(event, compute_s=total, search_s=new.search_time_s), None
    outcome = ReplanOutcome.PLANNED if new.success else ReplanOutcome.PARTIAL
    event = ReplanEvent(t_switch, reason, mu, mass, ready[0], t_switch + ready[0], outcome, new.status)
    return dataclasses.replace(event, segment_ready_s=tuple(ready), compute_s=total, search_s=new.search_time_s), new


def out_of_time(refusal) -> bool:
    """The search refusal says its time budget ran out (in a tree, a grid's search or any grid)."""
    if isinstance(refusal, Refusal):
        return refusal.kind is RefusalKind.TIME_BUDGET or out_of_time(refusal.cause)
    if isinstance(refusal, NoPlan):
        return refusal.last_searched is not None and out_of_time(refusal.last_searched.refusal)
    if isinstance(refusal, OnGrids):
        return any(out_of_time(why) for _, why in refusal.grids)
    return False
