"""Replanning during execution (simulate --replan): the closed loop plans again from the measured
state when what it measures says the plan no longer holds.

At each node of the plan being executed (where every finger holds the object at rest, the moment a
plan may start from), the closed loop's estimates and monitor are read: when the friction estimate
has fallen `friction_drop` below the plan's, the mass estimate is `mass_change` off the plan's, the
object is `theta_error` or `position_error` off its planned pose, or a finger the plan holds with
is out of contact, the planner runs from the measured state (trajectotree.planning.start) to the
same goal, with the estimated friction and mass.

Honest timing: the simulated world does not wait for the planner. The new plan takes effect only
after its measured wall-clock compute time has passed in simulated time; until then the controller
holds the measured state with the forces the old plan had at the node. A start the planner refuses,
or a search without a plan at the estimated friction, is recorded with its reason and the old plan
goes on. Each phase is the same execution Diagram built around the spliced reference, continued
from the previous phase's full state (plant, controller and estimators).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator

from trajectotree.config import Config, ConfigError
from trajectotree.execution import metrics
from trajectotree.execution.reference import Reference, reference_from_plan
from trajectotree.execution.simulate import Conditions, build_execution_diagram, collected_log
from trajectotree.planning.planners import plan as make_plan
from trajectotree.results import ClosedLoopLog, PlanResult, ReplanEvent, ReplanReason, SimLog, SimResult
from trajectotree.scene.plant import NUM_FINGERS, Scene, build_scene
from trajectotree.start import StartState

# s, over which the reference moves from the old plan's node to the measured state while the planner runs
HOLD_RAMP = 0.05


@dataclass(frozen=True)
class Phase:
    """The plan being executed from `start_s` on, its nodes at absolute simulated times."""

    plan: PlanResult
    start_s: float
    node_times: np.ndarray  # (N,) s


def node_times(plan: PlanResult, start_s: float) -> np.ndarray:
    """The absolute times of `plan`'s nodes (its segments span knots_per_segment knots)."""
    m = plan.config.cito.knots_per_segment
    return start_s + np.asarray(plan.trajectory.t)[::m] - plan.trajectory.t[0]


def replan_reason(execution, context, plan: PlanResult, config: Config) -> ReplanReason | None:
    """Why the plan no longer holds, from the closed loop's outputs at this moment (None: it holds)."""
    value = {
        name: closed_loop_output(execution, context, system, name)
        for system, name in (
            ("friction_estimator", "mu_estimate"),
            ("mass_estimator", "mass_estimate"),
            ("contact_monitor", "tracking_error"),
            ("contact_monitor", "in_contact"),
        )
    }
    rules = config.sim.replan
    assumed = plan.config.scene
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


def closed_loop_output(execution, context, system: str, port: str) -> np.ndarray:
    """The value of the closed-loop `system`'s output `port` (trajectotree.execution.closed_loop) now."""
    sub = execution.diagram.GetSubsystemByName(system)
    return sub.GetOutputPort(port).Eval(sub.GetMyContextFromRoot(context))


def estimates(execution, context) -> tuple[float, float]:
    """(friction, mass kg) as the closed loop estimates them now."""
    return (
        float(closed_loop_output(execution, context, "friction_estimator", "mu_estimate")[0]),
        float(closed_loop_output(execution, context, "mass_estimator", "mass_estimate")[0]),
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
    p_WF_at = np.stack([np.interp(t_switch, old.t, old.p_WF[:, i, a]) for i in range(NUM_FINGERS) for a in (0, 1)])
    t = np.concatenate([old.t[keep], hold_t, t_new + new.t])
    x = np.concatenate([old.x[keep], hold_x, new.x])
    q = np.concatenate([old.q[keep], [hold_q, q0], new.q])
    p = np.concatenate([old.p_WF[keep], [p_WF_at.reshape(NUM_FINGERS, 2), p_WF], new.p_WF])
    v = np.concatenate([old.v_WF[keep], np.zeros((2, NUM_FINGERS, 2)), new.v_WF])
    f = np.concatenate([old.f_W[keep], [f_at, f_at], new.f_W])
    xdot = np.concatenate([_xdot(old)[keep], np.zeros((2, 3)), _xdot(new)])
    return Reference(t=t, x=x, q=q, p_WF=p, v_WF=v, f_W=f, xdot=xdot)


def _xdot(reference: Reference) -> np.ndarray:
    return reference.xdot if reference.xdot is not None else np.gradient(reference.x, reference.t, axis=0)


def simulate_replanning(
    plan: PlanResult, config: Config, *, conditions: Conditions | None = None, segment_workers: int | None = None
) -> SimResult:
    """Executes `plan` closed loop (grasp controller) in the world of `conditions`, replanning at its
    nodes as the module doc says; the whole run, its replans in `replans`."""
    if plan.trajectory is None:
        raise ConfigError("simulate --replan: the plan has no trajectory")
    conditions = conditions or Conditions()
    scene = build_scene(config.scene)
    reference = reference_from_plan(plan, scene)
    phase, events, logs, context, started = Phase(plan, 0.0, node_times(plan, 0.0)), [], [], None, time.perf_counter()
    conditions_json = conditions.to_json(config.scene)
    while True:
        execution = build_execution_diagram(reference, config, conditions=conditions, closed_loop=True)
        simulator = Simulator(execution.diagram, execution.initial_context(reference))
        if context is not None:  # the same systems: the state carries over (SceneGraph's geometry ids do not)
            simulator.get_mutable_context().SetTime(context.get_time())
            simulator.get_mutable_context().get_mutable_discrete_state().SetFrom(context.get_discrete_state())
        simulator.Initialize()
        now = simulator.get_context().get_time()
        reason = None
        can_replan = len(events) < config.sim.replan.max_replans
        for t_node in phase.node_times[1:-1] if can_replan else ():
            if t_node <= now + 1e-9:
                continue
            simulator.AdvanceTo(t_node)
            reason = replan_reason(execution, simulator.get_context(), phase.plan, config)
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
        assumed = dataclasses.replace(config.scene, mu=mu, box_mass=mass)
        t0 = time.perf_counter()
        try:
            new = make_plan(
                goal=plan.goal if plan.config.goal.theta is None else plan.config.goal,  # with its position
                start=start,
                config=dataclasses.replace(config, scene=assumed),
                segment_workers=segment_workers,
            )
            status, planned = new.status, new.success
        except ConfigError as refused:  # a start the planner refuses (StartRefused): the old plan goes on
            new, status, planned = None, str(refused), False
        latency = time.perf_counter() - t0
        events.append(ReplanEvent(t_switch, reason, mu, mass, latency, t_switch + latency, planned, status))
        context = simulator.get_context().Clone()
        if planned:
            reference = spliced(reference, t_switch, start, scene, reference_from_plan(new, scene), t_switch + latency)
            phase = Phase(new, t_switch + latency, node_times(new, t_switch + latency))
        else:
            phase = dataclasses.replace(phase, node_times=phase.node_times[phase.node_times > t_switch + 1e-9])
    log = _joined(logs, reference, time.perf_counter() - started)
    return dataclasses.replace(metrics.evaluate(log, config.sim.drop_distance), replans=tuple(events))


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
