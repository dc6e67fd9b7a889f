"""Replanning during execution (simulate --replan): the closed loop plans again from the measured
state when what it measures says the plan no longer holds.

At each node of the plan being executed (where every finger holds the object at rest, the moment a
plan may start from), the closed loop's estimates and monitor are read: when the friction estimate
has fallen `friction_drop` below the plan's, the mass estimate is `mass_change` off the plan's, the
object is `theta_error` or `position_error` off its planned pose, or a finger the plan holds with
is out of contact, the planner runs from the measured state (trajectotree.planning.start) to the
same goal, with the estimated friction and mass.

Honest timing: the simulated world does not wait for the planner. While it runs, the controller
holds the measured state (with the old plan's forces at the node). The planner solves the new
plan's first segment before the others (keyframes.solve_first_segment_first) and the new plan takes
effect once that segment's measured wall-clock compute time has passed in simulated time; each later
segment begins no earlier than its own measured readiness (the last attempt of it and of its two
neighbours, whose joint retries could replace it), so the hand holds at a node while a segment is not
ready. The search gets controller.replan.search_deadline_s, and the first segment must be ready within
first_segment_deadline_s of the measured state. A
start the planner refuses, a search without a plan (in time or at all) or a first segment that fails
(or is not solved in time) is recorded with its typed reason
(results.ReplanOutcome, the refusal) and the old plan resumes after the same hold; a plan whose later
segment failed is executed up to that segment and planned again from there. Each phase is the same
execution Diagram built around the spliced reference, continued from the previous phase's full state
(plant, controller and estimators).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator

from trajectotree.config import Config, ConfigError, SceneConfig
from trajectotree.config.executor import Executor
from trajectotree.execution import metrics
from trajectotree.execution.reference import Reference, reference_from_arrays, reference_from_plan
from trajectotree.execution.simulate import Conditions, build_execution_diagram, collected_log
from trajectotree.planning.planners import plan as make_plan
from trajectotree.planning.start import StartRefused
from trajectotree.refusal import NoPlan, OnGrids, Refusal, RefusalKind
from trajectotree.results import (
    ClosedLoopLog,
    PlanResult,
    ReplanEvent,
    ReplanOutcome,
    ReplanReason,
    SimLog,
    SimResult,
)
from trajectotree.scene.plant import Scene, build_scene
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

    def after(self, t: float, delay: float = 0.0) -> Phase:
        """The checks after `t`, `delay` later (the old plan resuming after a hold)."""
        end = None if self.ends_short_s is None else self.ends_short_s + delay
        return Phase(tuple(c + delay for c in self.checks if c > t + 1e-9), end)


def node_times(plan: PlanResult, start_s: float) -> np.ndarray:
    """The absolute times of `plan`'s nodes (its segments span knots_per_segment knots)."""
    m = plan.config.cito.knots_per_segment
    return start_s + np.asarray(plan.trajectory.t)[::m] - plan.trajectory.t[0]


def replan_reason(execution, context, assumed: SceneConfig, config: Config) -> ReplanReason | None:
    """Why the plan in effect, which assumes the scene `assumed` (its friction and mass), no longer
    holds, from the closed loop's outputs at this moment (None: it holds)."""
    value = {
        name: closed_loop_output(execution, context, name)
        for name in ("mu_estimate", "mass_estimate", "tracking_error", "in_contact")
    }
    rules = config.controller.replan
    if value["mu_estimate"][0] < assumed.mu - rules.friction_drop:
        return ReplanReason.FRICTION
    if abs(value["mass_estimate"][0] - assumed.box_mass) > rules.mass_change * assumed.box_mass:
        return ReplanReason.MASS
    error = value["tracking_error"]
    if abs(error[2]) > rules.theta_error or np.hypot(error[0], error[1]) > rules.position_error:
        return ReplanReason.TRACKING
    if np.any(value["in_contact"] < 0.5):
        return ReplanReason.CONTACT_LOST
    return None


def closed_loop_output(execution, context, port: str) -> np.ndarray:
    """The value of the executor's closed-loop output `port` (trajectotree.execution.executor) now."""
    diagram = execution.executor.diagram
    return diagram.GetOutputPort(port).Eval(diagram.GetMyContextFromRoot(context))


def estimates(execution, context) -> tuple[float, float]:
    """(friction, mass kg) as the closed loop estimates them now."""
    return (
        float(closed_loop_output(execution, context, "mu_estimate")[0]),
        float(closed_loop_output(execution, context, "mass_estimate")[0]),
    )


def measured_start(execution, context) -> StartState:
    plant = execution.plant
    plant_context = plant.GetMyContextFromRoot(context)
    x = plant.GetPositions(plant_context, execution.box)
    return StartState(
        object_pose=tuple(x),
        q=tuple(plant.GetPositions(plant_context, execution.hand)),
        object_velocity=tuple(plant.GetVelocities(plant_context, execution.box)),
    )


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


def simulate_replanning(
    plan: PlanResult, config: Config, *, conditions: Conditions | None = None, segment_workers: int | None = None
) -> SimResult:
    """Executes `plan` closed loop (grasp controller) in the world of `conditions`, replanning at its
    nodes as the module doc says (the later segments of a new plan on `segment_workers`, as
    planning.planners.plan takes them); the whole run, its replans in `replans`."""
    if plan.trajectory is None:
        raise ConfigError("simulate --replan: the plan has no trajectory")
    conditions = conditions or Conditions()
    scene = build_scene(config.scene)
    reference = reference_from_plan(plan, scene)
    phase = Phase(tuple(node_times(plan, 0.0)[1:-1]))
    events, logs, context, started = [], [], None, time.perf_counter()
    conditions_json = conditions.to_json(config.scene)
    assumed = plan.config.scene  # what the plan in effect assumes (the last new plan's estimates)
    while True:
        execution = build_execution_diagram(
            reference, config, executor=Executor.GRASP_REPLAN, conditions=conditions, mu_assumed=assumed.mu
        )
        simulator = Simulator(execution.diagram, execution.initial_context(reference))
        if context is not None:  # the same systems: the state carries over (SceneGraph's geometry ids do not)
            simulator.get_mutable_context().SetTime(context.get_time())
            simulator.get_mutable_context().get_mutable_discrete_state().SetFrom(context.get_discrete_state())
            reflex = execution.executor.landing_reflex
            reflex.restart(reflex.GetMyMutableContextFromRoot(simulator.get_mutable_context()))
        simulator.Initialize()
        now = simulator.get_context().get_time()
        reason = None
        checks = [(t, None) for t in phase.checks]
        if phase.ends_short_s is not None:
            checks.append((phase.ends_short_s, ReplanReason.PLAN_ENDS_SHORT))
        for t_check, forced in checks if len(events) < config.controller.replan.max_replans else ():
            if t_check <= now + 1e-9:
                continue
            simulator.AdvanceTo(t_check)
            reason = replan_reason(execution, simulator.get_context(), assumed, config) or forced
            if reason is not None:
                break
        if reason is None:
            simulator.AdvanceTo(execution.duration)
            logs.append(collected_log(execution, simulator, reference, conditions_json, 0.0))
            break
        t_switch = simulator.get_context().get_time()
        logs.append(collected_log(execution, simulator, reference, conditions_json, 0.0))
        start = measured_start(execution, simulator.get_context())
        mu, mass = estimates(execution, simulator.get_context())
        event, new = replan(plan, config, start, t_switch, reason, mu, mass, scene, segment_workers)
        events.append(event)
        context = simulator.get_context().Clone()
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
            phase = phase.after(t_switch, event.latency_s)
    log = _joined(logs, reference, time.perf_counter() - started)
    result = metrics.evaluate(log, config.sim.drop_distance, config.scene.gravity, conditions.push_speed(config.scene))
    return dataclasses.replace(result, replans=tuple(events))


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


def _joined(logs: list[SimLog], reference: Reference, sim_time_s: float) -> SimLog:
    """The phases' logs as one run: each phase's samples before the next one begins."""
    ends = [nxt.t[0] - 1e-9 for nxt in logs[1:]] + [np.inf]
    pieces = [log.t < end for log, end in zip(logs, ends)]
    t = np.concatenate([log.t[keep] for log, keep in zip(logs, pieces)])
    closed = None
    if logs[0].closed_loop is not None:
        arrays = [log.closed_loop.arrays() for log in logs]
        closed = ClosedLoopLog(
            **{name: np.concatenate([a[name][keep] for a, keep in zip(arrays, pieces)]) for name in arrays[0]}
        )
    return dataclasses.replace(
        logs[0],
        t=t,
        x=np.concatenate([log.x[keep] for log, keep in zip(logs, pieces)]),
        q=np.concatenate([log.q[keep] for log, keep in zip(logs, pieces)]),
        x_plan=reference.object_pose_at(t),
        f_W=np.concatenate([log.f_W[keep] for log, keep in zip(logs, pieces)]),
        f_W_plan=reference.forces_at(t),
        sim_time_s=sim_time_s,
        closed_loop=closed,
    )
