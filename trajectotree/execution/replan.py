"""Replanning during execution (executor grasp-replan): the `Replanner`, a system of the execution
Diagram, plans again when what the closed loop measures says the plan no longer holds, and swaps the new
plan in; one Diagram and one Simulator run the whole execution.

The Replanner keeps the plan in effect in abstract state (a `Replanning`: the PlanInEffect, the nodes
still to check, the friction and mass the plan assumes, the replans so far, a swap decided but not yet
made) and puts the PlanInEffect on its output port `plan`, which feeds the `plan` input of every system
that follows the plan (the grasp controller, the landing reflex, the contact monitor and the friction
estimator: execution.in_effect), so that a swap reaches them all at once. Its periodic unrestricted
update (at controller.rate_hz) looks, at the first update at or after each node of the plan in effect
(where every finger holds the object at rest), at the closed loop's estimates and monitor through its
input ports: when the friction estimate has fallen `friction_drop` below the plan's, the mass estimate
is `mass_change` off the plan's, the object is `theta_error` or `position_error` off its planned pose,
or a finger the plan holds with is out of contact, the planner runs (trajectotree.planning.start) to
the same goal, with the estimated friction and mass, from one of two starts:

- The next node (the default): the hand goes on along its plan while the planner runs, and the new
  plan starts from the plan in effect's next node, its planned state (every finger on the object, at
  rest). The search gets the time to that node less controller.replan.first_segment_reserve_s, the
  first segment the time to that node, neither more than a replan from the measured state gets; a plan
  ready in time is swapped in at that node (the update at or after it), and one that is not
  (ReplanOutcome.LATE) or no plan at all leaves the old plan going on, which cost the hand nothing.
  A node followed only by the goal has nothing to plan from: no replan.
- The measured state, the hand holding at the node while the planner runs (a plan that ended short of
  its goal, and with controller.replan.measured_start_on_error a tracking error or a lost contact, for
  which the next node may be wrong): the search gets search_deadline_s, the first segment must be ready
  first_segment_deadline_s after the state was measured, and a refusal lets the old plan resume after
  the same hold.

Honest timing: the planner runs inside the update, so the simulated world stands still while it
computes, and its wall-clock compute time (the search and the new plan's first segment, solved before
the others: keyframes.solve_first_segment_first) is measured; a new plan never takes effect before that
time has passed in simulated time after the update that started it. From the next node, a plan whose
compute time exceeds the simulated time to that node is refused as late; from the measured state, the
plan swapped in at the update's time t_switch holds the measured state (with the old plan's forces at
the node) until t_switch + that time, as the hand would hold while a real planner ran. Each later
segment begins no earlier than its own measured readiness (its own last attempt: no joint retry of a
neighbour replaces it, keyframes.solve_first_segment_first), counted from the same update, so the hand
holds at a node while a segment is not ready. A start the planner refuses, a search without a plan (in time or at
all) or a first segment that fails (or is not solved in time) is recorded with its typed reason
(results.ReplanOutcome, the refusal); a plan whose later segment failed is executed up to that segment
and planned again from there (from the measured state). The run ends at the end of the plan in effect
(and config.sim.settle_time of hold): a swap moves it (executor.ExecutorSystems.advance_to_end).

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


def replan_reason(values: dict, assumed: SceneConfig, config: Config, off_plan=None) -> ReplanReason | None:
    """Why the plan in effect, which assumes the scene `assumed` (its friction and mass), no longer
    holds, from the closed loop's `values` now (mu_estimate, mass_estimate, tracking_error, in_contact;
    None: it holds); `off_plan` turns the tracking error into (rad, m) off the planned pose (None: the
    plane's, planar_off_plan)."""
    rules = config.controller.replan
    if values["mu_estimate"][0] < assumed.mu - rules.friction_drop:
        return ReplanReason.FRICTION
    if abs(values["mass_estimate"][0] - assumed.box_mass) > rules.mass_change * assumed.box_mass:
        return ReplanReason.MASS
    angle, distance = (off_plan or planar_off_plan)(values["tracking_error"])
    if angle > rules.theta_error or distance > rules.position_error:
        return ReplanReason.TRACKING
    if np.any(values["in_contact"] < 0.5):
        return ReplanReason.CONTACT_LOST
    return None


def planar_off_plan(error) -> tuple[float, float]:
    """(rad, m) off the planned pose, of the plane's tracking error (3: m, m, rad)."""
    return abs(error[2]), float(np.hypot(error[0], error[1]))


@dataclass(frozen=True)
class Deadlines:
    """A replan's wall-clock deadlines, s after it starts: its contact search's and its first segment's (all
    its attempts, the search included)."""

    search_s: float
    first_segment_s: float


# s, the least a search from the next node is given (when that node is nearer than first_segment_reserve_s): it
# then refuses at once, as late
MIN_SEARCH_S = 1e-3

# The reasons for which the plan's next node may be wrong (the hand is off its plan).
ERROR_REASONS = (ReplanReason.TRACKING, ReplanReason.CONTACT_LOST)


@dataclass(frozen=True, eq=False)
class Swap:
    """A new plan decided at one update, which takes effect at `at_s` (the node it starts from): the `plan`
    in effect from then, its `phase` and the scene it `assumed`."""

    at_s: float  # s
    plan: PlanInEffect
    phase: Phase
    assumed: SceneConfig


@dataclass(frozen=True, eq=False)
class Replanning:
    """The Replanner's state: the `plan` in effect, the `phase` (its nodes still to check), the scene
    it `assumed` (the last new plan's estimates of friction and mass), the `events` (each replan) and the
    `pending` swap (a new plan from the next node, not yet in effect)."""

    plan: PlanInEffect
    phase: Phase
    assumed: SceneConfig
    events: tuple[ReplanEvent, ...] = ()
    pending: Swap | None = None

    def __deepcopy__(self, memo) -> Replanning:
        # Immutable: Drake copies abstract state at each unrestricted update; a copy shares it.
        return self

    def at(self, t: float) -> Replanning:
        """This state at `t`: the pending swap made once its node is reached."""
        swap = self.pending
        if swap is None or swap.at_s > t + 1e-9:
            return self
        return Replanning(swap.plan, swap.phase, swap.assumed, self.events)

    def next_node_s(self, rest: Phase) -> float | None:
        """s, the plan in effect's next node after a check whose later checks are `rest`: the next check, or
        the end of a plan that ends short of its goal; None: the next node is the goal."""
        if rest.checks:
            return rest.checks[0]
        return None if rest.ends_short_s is None else float(self.plan.reference.t[-1])


class Replanner(LeafSystem):
    """Replans, during its execution, the plan of `planning` (PlanePlanning, or in space execution.space_replan.
    SpacePlanning: the planner, the goal, the executing config and the state's shape) (module doc).
    Input ports: `box_state` (the object's joint state: in the plane 6, x m, y m, theta rad and their rates; in
    space 13, [qw qx qy qz px py pz] and [w_W v_W]), `hand_state` (the hand's [q rad; v rad/s]), `mu_estimate`
    (1), `mass_estimate` (1, kg), `tracking_error` (the plane's 3: m, m, rad; space's 6: rad, m) and `in_contact`
    (F, 1/0), the closed loop's outputs of those names. Output port `plan` (abstract: the PlanInEffect).
    `initial`: the plan in effect at the start."""

    def __init__(self, planning, initial: PlanInEffect):
        super().__init__()
        self._planning, self._config = planning, planning.config
        start = Phase(tuple(planning.node_times()[1:-1]))
        self._state = self.DeclareAbstractState(
            AbstractValue.Make(Replanning(initial, start, planning.first_assumed()))
        )
        self.box_state_port = self.DeclareVectorInputPort("box_state", planning.box_state_size)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * planning.num_joints)
        self._estimate_ports = {
            name: self.DeclareVectorInputPort(name, size)
            for name, size in (
                ("mu_estimate", 1),
                ("mass_estimate", 1),
                ("tracking_error", planning.tracking_error_size),
            )
        }
        self._estimate_ports["in_contact"] = self.DeclareVectorInputPort("in_contact", planning.num_fingers)
        self.plan_port = self.DeclareAbstractOutputPort(
            PLAN_PORT, lambda: AbstractValue.Make(initial), self.CalcPlan, {self.abstract_state_ticket(self._state)}
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / self._config.controller.rate_hz, 0.0, self._Update)

    def replanning(self, context) -> Replanning:
        """The state in this system's `context`."""
        return context.get_abstract_state(self._state).get_value()

    def end_s(self, context) -> float:
        """s, when the run ends: the plan in effect's end, then config.sim.settle_time of hold."""
        return self.replanning(context).plan.reference.duration + self._config.sim.settle_time

    def CalcPlan(self, context, output):
        output.set_value(self.replanning(context).plan)

    def _Update(self, context, state):
        before = self.replanning(context)
        t = context.get_time()
        now = before.at(t)
        checked, forced, rest = now.phase.due(t)
        if checked and len(now.events) < self._config.controller.replan.max_replans:
            values = {name: port.Eval(context) for name, port in self._estimate_ports.items()}
            reason = replan_reason(values, now.assumed, self._config, self._planning.off_plan) or forced
            if reason is None:
                now = dataclasses.replace(now, phase=rest)
            elif forced is None and not self.holds_for(reason):
                now = self.replanned_ahead(context, now, reason, rest)
            else:
                now = self.replanned(context, now, reason)
        elif now is before:
            return EventStatus.DidNothing()
        state.get_mutable_abstract_state(self._state).set_value(now)
        return EventStatus.Succeeded()

    def holds_for(self, reason: ReplanReason) -> bool:
        """A replan for `reason` plans from the measured state, the hand holding (else from the next node):
        always in space (its planner takes longer than a segment lasts)."""
        if self._planning.always_holds:
            return True
        return self._config.controller.replan.measured_start_on_error and reason in ERROR_REASONS

    def measured_start(self, context):
        return self._planning.measured_start(self.box_state_port.Eval(context), self.hand_state_port.Eval(context))

    def estimates(self, context) -> tuple[float, float]:
        """The friction and mass (kg) estimates now."""
        return tuple(float(self._estimate_ports[name].Eval(context)[0]) for name in ("mu_estimate", "mass_estimate"))

    def replanned_ahead(self, context, now: Replanning, reason: ReplanReason, rest: Phase) -> Replanning:
        """The state after planning at this update for `reason` from the next node's planned state while the
        hand goes on along its plan (the world stands still meanwhile): a new plan ready before the hand
        reaches that node is swapped in there (pending until then); otherwise the old plan goes on."""
        t, t_node = context.get_time(), now.next_node_s(rest)
        if t_node is None:  # the next node is the goal: nothing left to plan
            return dataclasses.replace(now, phase=rest)
        lead, rules = t_node - t, self._config.controller.replan
        # no more time than a replan from the measured state gets: a far node leaves slack before the swap
        # rather than a longer latency
        deadlines = Deadlines(
            min(max(lead - rules.first_segment_reserve_s, MIN_SEARCH_S), rules.search_deadline_s),
            min(lead, rules.first_segment_deadline_s),
        )
        planning = self._planning
        start = planning.node_state(now.plan.reference, t_node)
        mu, mass = self.estimates(context)
        event, solved = replan(planning, start, t, reason, mu, mass, deadlines)
        event = dataclasses.replace(event, start_s=t_node)
        if event.planned and event.latency_s > lead:
            event, solved = dataclasses.replace(event, outcome=ReplanOutcome.LATE), None
        if solved is None:  # the old plan goes on, the hand never stopped
            return Replanning(now.plan, rest, now.assumed, now.events + (dataclasses.replace(event, takes_effect_s=t),))
        event = dataclasses.replace(event, takes_effect_s=t_node)
        following, phase = self.executed(solved.new, event)
        reference = planning.joined(now.plan.reference, t_node, following)
        swapped = planning.in_effect(reference, solved.assumed.mu, now.plan.version + 1)
        pending = Swap(t_node, swapped, phase, solved.assumed)
        return Replanning(now.plan, rest, now.assumed, now.events + (event,), pending)

    def replanned(self, context, now: Replanning, reason: ReplanReason) -> Replanning:
        """The state after planning again at this update for `reason` from the measured state, the hand
        holding while the planner runs (the world stands still meanwhile)."""
        t_switch, planning, start = context.get_time(), self._planning, self.measured_start(context)
        mu, mass = self.estimates(context)
        event, solved = replan(planning, start, t_switch, reason, mu, mass)
        event = dataclasses.replace(event, start_s=t_switch)
        reference, assumed = now.plan.reference, now.assumed
        if event.planned:
            following, phase = self.executed(solved.new, event)
            reference = planning.spliced(reference, t_switch, start, following, event.takes_effect_s)
            assumed = solved.assumed
        else:  # the hand held while the planner ran: the old plan resumes that much later
            reference = planning.delayed(reference, t_switch, event.latency_s)
            phase = now.phase.after(t_switch, event.latency_s)
        swapped = planning.in_effect(reference, assumed.mu, now.plan.version + 1)
        return Replanning(swapped, phase, assumed, now.events + (event,))

    def executed(self, new, event: ReplanEvent) -> tuple[Reference, Phase]:
        """The new plan of `event` as executed from event.takes_effect_s: its reference from 0 (each segment
        beginning no earlier than it was ready, counted from event.time_s: scheduled; up to a failed one) and
        its phase in absolute times (a plan that ends short plans again at its last node, once the failure
        is known)."""
        m = self._planning.knots_per_segment(new)
        usable = next((k for k, r in enumerate(event.segment_ready_s) if not np.isfinite(r)), None)
        arrays = new.trajectory.arrays()
        if usable is not None:  # the segments before the failed one
            arrays = {name: values[: usable * m + 1] for name, values in arrays.items()}
        offset = event.takes_effect_s - event.time_s
        ready = [r - offset for r in event.segment_ready_s]
        reference, arrivals = self._planning.scheduled(self._planning.reference_of(arrays), m, ready)
        arrivals = event.takes_effect_s + arrivals
        if usable is None:
            return reference, Phase(tuple(arrivals[1:-1]))
        return reference, Phase(tuple(arrivals[1:-1]), max(arrivals[-1], event.time_s + event.compute_s))


def node_state(reference: Reference, t: float) -> StartState:
    """`reference`'s planned state at `t`, a node of it: every finger on the object, at rest."""
    q = [np.interp(t, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])]
    return StartState(object_pose=tuple(reference.object_pose_at([t])[0]), q=tuple(q))


def joined(old: Reference, t_node: float, new: Reference) -> Reference:
    """`old` up to `t_node` (a node of it), then `new`, which begins at that node's state, from `t_node`."""
    keep = old.t < t_node - 1e-9

    def cat(before: np.ndarray, after: np.ndarray) -> np.ndarray:
        return np.concatenate([before[keep], after])

    return Reference(
        t=np.concatenate([old.t[keep], t_node + new.t - new.t[0]]),
        x=cat(old.x, new.x),
        q=cat(old.q, new.q),
        p_WF=cat(old.p_WF, new.p_WF),
        v_WF=cat(old.v_WF, new.v_WF),
        f_W=cat(old.f_W, new.f_W),
        xdot=cat(_xdot(old), _xdot(new)),
        p_WC=None if old.p_WC is None or new.p_WC is None else cat(old.p_WC, new.p_WC),
    )


def schedule_rows(t: np.ndarray, knots_per_segment: int, ready: list[float]) -> tuple[list, list, np.ndarray]:
    """The knots (index into `t`, s from 0) of a plan whose segment k (knots_per_segment knots) may begin no
    earlier than ready[k] s after segment 0 begins (ready[0] = 0, inf: never): where a segment is not ready at
    its node that node repeats (held until it is), and it ends at the first segment that never is. Also the
    times the nodes are reached (node 0 at 0)."""
    m = knots_per_segment
    t = t - t[0]
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
    return index, times, np.asarray(arrivals)


def scheduled(new: Reference, knots_per_segment: int, ready: list[float]) -> tuple[Reference, np.ndarray]:
    """`new` (segments of knots_per_segment knots) as executed when its segment k may begin no earlier
    than ready[k] s after segment 0 begins (schedule_rows): where a segment is not ready at its node the
    reference holds that node (a static grasp: zero velocities). Also the times the nodes are reached."""
    index, times, arrivals = schedule_rows(new.t, knots_per_segment, ready)
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
    return held, arrivals


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


@dataclass(frozen=True)
class Solved:
    """What a dimension's planner gave: the `new` plan, when each of its segments was ready (s after the
    replan began, inf: never), whether its first segment came `late` (after its deadline), whether a plan that
    failed is executed up to its failed segment (`partial`: segments planned apart) and the scene it
    `assumed` (the estimated friction and mass)."""

    new: object  # results.PlanResult or planning.spatial.SpacePlanResult
    ready: tuple[float, ...]
    late: bool
    partial: bool
    assumed: SceneConfig


@dataclass(frozen=True, eq=False)
class PlanePlanning:
    """The Replanner's planner and plan in the plane: `plan` (a PlanResult: its goal) executed with `config` in
    `scene`, a new plan's later segments on `segment_workers` local processes (None: as planning.planners.plan
    takes them). Its object state is the planar joint's (6), its tracking error (3: m, m, rad)."""

    plan: PlanResult
    config: Config
    scene: Scene
    segment_workers: int | None

    box_state_size = 6
    tracking_error_size = 3
    always_holds = False  # a changed estimate plans from the next node, the hand going on
    off_plan = staticmethod(planar_off_plan)
    node_state = staticmethod(node_state)
    joined = staticmethod(joined)
    delayed = staticmethod(delayed)

    @property
    def num_joints(self) -> int:
        return self.scene.num_hand_joints

    @property
    def num_fingers(self) -> int:
        return self.scene.num_fingers

    def first_assumed(self) -> SceneConfig:
        """The scene the first plan assumed."""
        return self.plan.config.scene

    def node_times(self) -> np.ndarray:
        """s, the first plan's nodes."""
        return node_times(self.plan, 0.0)

    def deadlines(self) -> Deadlines:
        """A replan's from the measured state (controller.replan)."""
        rules = self.config.controller.replan
        return Deadlines(rules.search_deadline_s, rules.first_segment_deadline_s)

    def measured_start(self, box, hand) -> StartState:
        return StartState(object_pose=tuple(box[:3]), q=tuple(hand[: self.num_joints]), object_velocity=tuple(box[3:]))

    def solve(self, start: StartState, mu: float, mass: float, deadlines: Deadlines) -> Solved:
        """Plans from `start` to the plan's goal with friction `mu` and mass `mass` kg within `deadlines`, the
        first segment first (keyframes.solve_first_segment_first); StartRefused for a start it cannot plan from."""
        config = self.config
        assumed = dataclasses.replace(
            config,
            scene=dataclasses.replace(
                config.scene,
                mu=mu,
                box_mass=mass,
                object_inertia=None if config.scene.object_inertia is None else config.scene.inertia_zz(mass),
            ),
            search=dataclasses.replace(config.search, time_budget_s=deadlines.search_s, budget_clock="wall"),
        )
        first_first = config.cito.formulation == "keyframes"
        t0 = time.perf_counter()
        plan = self.plan
        new = make_plan(
            goal=plan.goal if plan.config.goal.theta is None else plan.config.goal,  # with its position
            start=start,
            config=assumed,
            scene=self.scene,  # the executed object's geometry, for the start's contacts (plan() rebuilds it)
            segment_workers=self.segment_workers,
            first_segment_first=first_first,
            first_segment_deadline_s=deadlines.first_segment_s if first_first else None,
        )
        total = time.perf_counter() - t0
        segments = max(len(new.contact_plan.nodes) - 1, 1)
        ready = new.segment_ready_s if first_first else (total,) * segments
        # ran out of time: segment 0's attempts came back no sooner than its deadline
        late = first_first and bool(ready) and ready[0] >= deadlines.first_segment_s
        # the joint formulation is one program: none of a failed one is executed
        return Solved(new, tuple(ready), late, first_first, new.config.scene)

    def knots_per_segment(self, new: PlanResult) -> int:
        return new.config.cito.knots_per_segment

    def reference_of(self, arrays: dict) -> Reference:
        return reference_from_arrays(arrays, self.scene)

    def in_effect(self, reference: Reference, mu: float, version: int) -> PlanInEffect:
        return plan_in_effect(reference, self.config, self.scene, mu, version)

    def scheduled(self, new: Reference, knots_per_segment: int, ready: list[float]) -> tuple[Reference, np.ndarray]:
        return scheduled(new, knots_per_segment, ready)

    def spliced(self, old: Reference, t_switch: float, start: StartState, new: Reference, t_new: float) -> Reference:
        return spliced(old, t_switch, start, self.scene, new, t_new)


def replan(
    planning,
    start,
    t_switch: float,
    reason: ReplanReason,
    mu: float,
    mass: float,
    deadlines: Deadlines | None = None,
) -> tuple[ReplanEvent, Solved | None]:
    """Plans with `planning` (PlanePlanning or space_replan.SpacePlanning) from `start` (measured, or a node's
    planned state) to its plan's goal with the estimated friction and mass, within `deadlines` (None: the
    planning's own from the measured state, the hand holding); the event (at `t_switch`) and what was solved
    (None: no plan to execute)."""
    deadlines = deadlines or planning.deadlines()
    t0 = time.perf_counter()
    try:
        solved = planning.solve(start, mu, mass, deadlines)
    except StartRefused as refused:  # the old plan goes on
        latency = time.perf_counter() - t0
        event = ReplanEvent(
            t_switch, reason, mu, mass, latency, t_switch + latency, ReplanOutcome.START_REFUSED, str(refused)
        )
        return dataclasses.replace(event, refusal=refused.refusal, compute_s=latency), None
    total = time.perf_counter() - t0
    new = solved.new
    searched = new.contact_plan
    if not searched.success:
        late = new.search_time_s >= deadlines.search_s or out_of_time(searched.refusal)
        outcome = ReplanOutcome.SEARCH_DEADLINE if late else ReplanOutcome.NO_PLAN
        event = ReplanEvent(t_switch, reason, mu, mass, total, t_switch + total, outcome, new.status)
        return dataclasses.replace(event, refusal=searched.refusal, compute_s=total, search_s=new.search_time_s), None
    ready = solved.ready
    if new.trajectory is None or not np.isfinite(ready[0]) or not (solved.partial or new.success):
        outcome = ReplanOutcome.FIRST_SEGMENT_LATE if solved.late else ReplanOutcome.FIRST_SEGMENT_FAILED
        event = ReplanEvent(t_switch, reason, mu, mass, total, t_switch + total, outcome, new.status)
        event = dataclasses.replace(event, compute_s=total, search_s=new.search_time_s, **first_segment_work(new))
        return event, None
    outcome = ReplanOutcome.PLANNED if new.success else ReplanOutcome.PARTIAL
    event = ReplanEvent(t_switch, reason, mu, mass, ready[0], t_switch + ready[0], outcome, new.status)
    timing = dict(compute_s=total, search_s=new.search_time_s, **first_segment_work(new))
    return dataclasses.replace(event, segment_ready_s=tuple(ready), **timing), solved


def first_segment_work(new) -> dict:
    """The ReplanEvent fields first_segment_s and first_segment_iterations of the plan `new`: its segment 0's
    attempts, from its segment records (none, as in space: the fields' defaults)."""
    records = getattr(new, "segments", ())
    if not records:
        return {}
    attempts = records[0]["attempts"]
    return dict(
        first_segment_s=sum(a["time_s"] for a in attempts),
        first_segment_iterations=sum(a["iterations"] for a in attempts),
    )


def out_of_time(refusal) -> bool:
    """The search refusal says its time budget ran out (in a tree, a grid's search or any grid)."""
    if isinstance(refusal, Refusal):
        return refusal.kind is RefusalKind.TIME_BUDGET or out_of_time(refusal.cause)
    if isinstance(refusal, NoPlan):
        return refusal.last_searched is not None and out_of_time(refusal.last_searched.refusal)
    if isinstance(refusal, OnGrids):
        return any(out_of_time(why) for _, why in refusal.grids)
    return False
