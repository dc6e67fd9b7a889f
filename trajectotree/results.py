"""The plain values the stages hand on from one to the next, and the names they are known by.

Planning yields a `PlanResult` (its `Trajectory` holds the plan.npz arrays, its
`PhysicsCheck` the check of those arrays); executing a plan yields a `SimLog`, which
`trajectotree.execution.metrics.evaluate` turns into a `SimResult` (the log and its tracking
metrics: sim.json and sim.npz). `trajectotree.io` saves and loads them all.

This module imports nothing that builds or runs anything (no Drake, no other stage),
so every stage, the sweep's Drake-free parent process included, may import it.
"""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass, field, fields
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from trajectotree.config import (
    GOAL_ROTATION_BOUND,
    ConfigError,
    GoalPose,
    check_goal_rotation,
    check_length,
    check_range,
)

if TYPE_CHECKING:  # annotations only: config and contact_plan are values too, loaded by io
    from trajectotree.config import Config
    from trajectotree.contact_plan import ContactPlan

METHODS = ("trajectotree", "cito", "cito-warm")  # the paper's method and its two baselines
# The plan.npz arrays (README, "Trajectory optimization"), in the order they are saved.
TRAJECTORY_ARRAYS = ("t", "x", "xdot", "q", "qdot", "tau", "lambda_n", "lambda_t", "f_W", "p_W_tip", "p_W_C")
# The sim.npz arrays (README, "Executing a plan").
SIM_ARRAYS = ("t", "x", "q", "x_plan", "abs_error", "f_W", "f_W_plan")
# The sim.npz arrays of a closed-loop run besides (ClosedLoopLog).
CLOSED_LOOP_ARRAYS = (
    "in_contact",
    "slipping",
    "force_ratio",
    "slip_speed",
    "tracking_error",
    "mu_estimate",
    "mass_estimate",
    "disturbance",
    "reflex",
)

# The physics check's rule (trajectotree.planning.physics; written into plan.json with each check):
GAP_TOL = 1e-4  # m, a fingertip sphere farther than this from the box is off it
FORCE_TOL = 0.01  # N, the most force a fingertip off the box may carry
CONE_TOL = 1e-6  # N, friction-cone violation tolerated (IPOPT holds the linear cone rows to ~1e-8)
NEWTON_EULER_TOL = 1e-4  # N and N m, Newton-Euler residual tolerated: 0.02 % of the default box's weight
# m, how deep a fingertip sphere may sink into the object: the smooth distance CITO's free fingers see
# lies up to log(2)/k = 0.7 mm above the exact one at a corner (cito.sdf_sharpness k)
PENETRATION_TOL = 1e-3
# m, how deep a finger link's collision box may overlap the object: the link rows keep 1 mm of
# smooth distance (cito.link_clearance), exact at a face
LINK_PENETRATION_TOL = 1e-3
# m, how deep two fingers' collision shapes (link boxes, fingertip spheres) may overlap: the link rule's
FINGER_OVERLAP_TOL = 1e-3


def check_method(method: str) -> str:
    if method not in METHODS:
        raise ConfigError(field="method", value=method, problem="is unknown", choices=METHODS)
    return method


def check_goal(goal, name: str = "goal") -> GoalPose:
    """The goal, checked: a rotation (rad, a number: the object keeps its start position), a pose
    (x m, y m, theta rad) or a GoalPose, its orientation within +-20 pi (ten turns either way) and
    its position within the scene's +-1 m. The one check of a goal, by the planners, the search and
    the CLI; ConfigError naming `name` (and the entry of a pose) otherwise. Whether the hand can
    carry the object there is the workspace's check (trajectotree.search.workspace)."""
    if isinstance(goal, GoalPose):
        if goal.theta is None:
            raise ConfigError(field=f"{name}.theta", problem="is not given", valid=GOAL_ROTATION_BOUND)
        return goal
    if isinstance(goal, (str, bytes)) or not hasattr(goal, "__len__"):
        return GoalPose(theta=check_goal_rotation(name, _number(goal)))
    check_length(name, goal, 3, "x m, y m, theta rad")
    for i in range(2):
        check_range(name, _number(goal[i]), -1.0, 1.0, index=(i,))
    theta = check_goal_rotation(name, _number(goal[2]), index=(2,))
    return GoalPose(theta=theta, position=(float(goal[0]), float(goal[1])))


def _number(value):
    """A numpy scalar as the Python number it holds (the checks take int and float)."""
    return value.item() if isinstance(value, np.generic) else value


@dataclass(frozen=True)
class Trajectory:
    """The plan at every knot (the plan.npz arrays)."""

    t: np.ndarray  # (K,) s
    x: np.ndarray  # (K, 3) object pose (x m, y m, theta rad)
    xdot: np.ndarray  # (K, 3)
    q: np.ndarray  # (K, 2F) rad, finger-major (F fingers: 4 for the default hand)
    qdot: np.ndarray  # (K, 2F) rad/s
    tau: np.ndarray  # (K, 2F) N m
    lambda_n: np.ndarray  # (K, F) N, normal force of each finger on the box
    lambda_t: np.ndarray  # (K, F) N, tangential force (along t_B = z x n_B)
    f_W: np.ndarray  # (K, F, 2) N, force of each finger ON the box, in W
    p_W_tip: np.ndarray  # (K, F, 2) m, fingertip positions in W: the sphere centres
    #                        (the hand description's tip frames)
    p_W_C: np.ndarray  # (K, F, 2) m, where each finger's force acts on the box surface, in W: the
    #                        planned contact of a pinned finger, else the box point nearest the tip

    def arrays(self) -> dict[str, np.ndarray]:
        """{plan.npz name: array}."""
        return {name: getattr(self, name) for name in TRAJECTORY_ARRAYS}


@dataclass(frozen=True)
class PhysicsCheck:
    """The check of a plan's arrays (trajectotree.planning.physics.check_physics)."""

    newton_euler_force_N: float  # max |translational residual| over knots, N
    newton_euler_moment_Nm: float  # max |rotational residual| over knots, N m
    friction_cone_N: float  # max cone violation (<= 0 inside), N
    mu: float  # the friction coefficient the cones were checked with
    force_at_distance_N: float  # max |f_W| of a fingertip more than GAP_TOL off the box (0 if none), N
    force_at_distance_knot: int  # where that force is (-1 if none)
    force_at_distance_finger: int
    force_at_distance_gap_m: float  # that fingertip's distance from the box, m
    contact_point_off_surface_m: float  # max distance of p_W_C from the box boundary, m
    penetration_m: float  # deepest any fingertip sphere sinks into the box (0 if none), m
    link_penetration_m: float  # deepest overlap of a finger link's collision box with the box, m (NaN: unchecked)
    link_penetration_knot: int  # where that is (-1 if nowhere)
    link_penetration_finger: int
    passed: bool
    reason: str  # why it failed ("" if passed)
    # m, the least signed distance between two fingers' collision shapes over the knots (negative: the
    # deepest overlap); NaN: unchecked (a plan.json from before the rule, or no hand given)
    finger_distance_m: float = float("nan")
    finger_distance_knot: int = -1  # where that is (-1: unchecked)
    finger_distance_fingers: tuple = ()  # the two fingers (i, j), i < j

    def to_json(self) -> dict:
        """The fields (non-finite numbers as None: JSON has no NaN) and the tolerances."""
        values = {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in asdict(self).items()}
        return {
            **values,
            "gap_tol_m": GAP_TOL,
            "force_tol_N": FORCE_TOL,
            "cone_tol_N": CONE_TOL,
            "newton_euler_tol": NEWTON_EULER_TOL,
            "penetration_tol_m": PENETRATION_TOL,
            "link_penetration_tol_m": LINK_PENETRATION_TOL,
            "finger_overlap_tol_m": FINGER_OVERLAP_TOL,
        }

    @staticmethod
    def from_json(data: dict) -> PhysicsCheck:
        """Fields a plan.json from before a rule existed lacks (penetration_m) read as NaN: unknown (the
        finger rule's as its defaults: unchecked)."""
        nan = float("nan")
        values = {f.name: nan if data.get(f.name) is None else data[f.name] for f in fields(PhysicsCheck)}
        values["finger_distance_knot"] = data.get("finger_distance_knot", -1)
        values["finger_distance_fingers"] = tuple(data.get("finger_distance_fingers", ()))
        return PhysicsCheck(**values)


@dataclass(frozen=True)
class PlanResult:
    method: str
    goal: float  # rad
    success: bool  # IPOPT converged, the physics check passed (the search too, where used)
    status: str  # IPOPT status name (+ why the physics check failed), or why the search failed
    search_time_s: float
    build_time_s: float
    solve_time_s: float
    total_time_s: float
    cost: float  # final objective (nan when nothing was solved)
    iterations: int  # IPOPT iterations (0 when nothing was solved)
    contact_plan: ContactPlan
    trajectory: Trajectory | None  # None when nothing was solved
    violations: dict  # max abs violation per group (solve.VIOLATION_GROUPS)
    config: Config
    solver_timing: dict = field(default_factory=dict)  # IPOPT's timing statistics, s
    physics_check: PhysicsCheck | None = None  # the check of the plan's arrays (None: nothing solved)
    # IPOPT converged (and the search found a plan, where used), whether or not the physics check
    # passed: the general CITO baselines converge to plans that push from a distance.
    converged: bool = False
    formulation: str = "joint"  # cito.formulation that made it (the baselines: always one joint program)
    # keyframes: per segment (plan.json "segments"): nodes, success, status, iterations, time_s,
    # retries and every attempt (trajectotree.planning.keyframes.segment_records); () for the joint program
    segments: tuple = ()
    # s after planning began, when each segment's trajectory was final (a first-segment-first plan, as
    # replanning makes: trajectotree.planning.keyframes.solve_first_segment_first; inf: not executable); ()
    # for a plan solved at once
    segment_ready_s: tuple[float, ...] = ()


@dataclass(frozen=True)
class ClosedLoopLog:
    """What the closed loop (trajectotree.execution.closed_loop) watched and estimated in one
    run, at the SimLog's sample times t (T,): sim.npz's CLOSED_LOOP_ARRAYS."""

    in_contact: np.ndarray  # (T, 4) bool, the finger (either link) pushes on the box
    slipping: np.ndarray  # (T, 4) bool, it pushes >= controller.estimators.slip_min_force and slides > slip_speed
    force_ratio: np.ndarray  # (T, 4) |f_t| / f_n of its force on the box (0 out of contact)
    slip_speed: np.ndarray  # (T, 4) m/s, relative tangential velocity at its contact points (fastest)
    tracking_error: np.ndarray  # (T, 3) measured - planned object pose (m, m, rad wrapped to [-pi, pi))
    mu_estimate: np.ndarray  # (T,) the friction estimate (starts at the plan's scene.mu)
    mass_estimate: np.ndarray  # (T,) kg, the object mass estimate (starts at the plan's)
    disturbance: np.ndarray  # (T, 2) N in W, the force on the object its contacts and gravity do not explain
    reflex: np.ndarray  # (T,) 0..1, the push reflex (1: squeeze and object gains fully raised)

    MONITOR_ARRAYS: ClassVar[tuple[str, ...]] = CLOSED_LOOP_ARRAYS[:5]  # the ContactMonitor's outputs

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in CLOSED_LOOP_ARRAYS}

    @classmethod
    def from_logged(cls, data: dict[str, np.ndarray]) -> ClosedLoopLog:
        """The log of the closed loop's output ports' samples, {name: (T, size)}: the flags as bools, the
        one-value outputs as (T,)."""
        data = dict(data)
        for name in ("in_contact", "slipping"):
            data[name] = data[name] > 0.5
        for name in ("mu_estimate", "mass_estimate", "reflex"):
            data[name] = data[name][:, 0]
        return cls(**data)

    def to_json(self, t: np.ndarray) -> dict:
        """sim.json's "closed_loop": the final estimates, how long each finger slid and the reflex was on."""
        dt = np.diff(t, append=t[-1])  # each sample stands for the time to the next
        return {
            "mu_estimate": float(self.mu_estimate[-1]),
            "mass_estimate": float(self.mass_estimate[-1]),
            "slipping_s": [float(np.sum(dt[self.slipping[:, i]])) for i in range(self.slipping.shape[1])],
            "reflex_s": float(np.sum(dt[self.reflex > 0.0])),
        }


@dataclass(frozen=True)
class SimLog:
    """What one execution of a plan recorded (trajectotree.execution.simulate), sampled at t."""

    t: np.ndarray  # (T,) s, sample times
    x: np.ndarray  # (T, 3) simulated object pose (x m, y m, theta rad)
    q: np.ndarray  # (T, 8) rad, simulated joint angles (finger-major)
    x_plan: np.ndarray  # (T, 3) planned object pose at the same times
    f_W: np.ndarray  # (T, 4, 2) N, simulated force of each finger on the box, in W
    f_W_plan: np.ndarray  # (T, 4, 2) N, planned force of each finger on the box at the same times
    sim_time_s: float  # s, wall-clock time of the simulation
    controller: str  # which executor ran (config.CONTROLLERS, or "none": zero torque)
    conditions: dict  # execution.world.Conditions.to_json() of the simulated world
    # What the closed loop watched and estimated (sim.npz's CLOSED_LOOP_ARRAYS besides SIM_ARRAYS, sim.json's
    # "closed_loop" summary); None: an open-loop run, whose sim.npz holds SIM_ARRAYS alone
    closed_loop: ClosedLoopLog | None = field(default=None, kw_only=True)
    # Drake's message when a step of the simulation threw (the samples end before it); None: it ran to the end
    step_error: str | None = field(default=None, kw_only=True)


# A run "held" its object when it did not drop it and ended this close to the plan's final pose (README, results).
FINAL_THETA_TOLERANCE = math.radians(3.0)  # rad
# m: the tracking error past which ReplanConfig.position_error says a plan no longer holds (10x a tracked plan's)
FINAL_POSITION_TOLERANCE = 0.005


class RunOutcome(enum.Enum):
    """How an execution ended (SimResult.outcome), as sim.json's "outcome" writes it."""

    HELD = "held"  # not dropped, and ended within FINAL_THETA_TOLERANCE and FINAL_POSITION_TOLERANCE of the plan
    OFF_PLAN = "off_plan"  # not dropped, but ended farther than that from the plan's final pose
    DROPPED = "dropped"  # the drop rule fired (trajectotree.execution.metrics.detect_drop)
    # the simulation stopped being physical: a state not finite, an object faster than any force could make it,
    # or Drake refusing a step (trajectotree.execution.metrics.detect_divergence); not a drop
    DIVERGED = "diverged"


class ReplanReason(enum.Enum):
    FRICTION = "the friction estimate fell below the plan's"
    MASS = "the mass estimate is off the plan's"
    TRACKING = "the object is off its planned pose"
    CONTACT_LOST = "a holding finger lost its contact"
    PLAN_ENDS_SHORT = "the plan in effect ends short of the goal (a later segment of it failed)"


class ReplanOutcome(enum.Enum):
    PLANNED = "a new plan took effect"
    PARTIAL = "a new plan took effect, but one of its later segments failed: the hand holds before it"
    START_REFUSED = "the planner refused the measured start: the old plan goes on"
    SEARCH_DEADLINE = (
        "the search found no plan within its deadline (controller.replan.search_deadline_s): the old plan goes on"
    )
    NO_PLAN = "the search found no plan at the estimated friction and mass: the old plan goes on"
    FIRST_SEGMENT_FAILED = "the new plan's first segment failed: the old plan goes on"
    FIRST_SEGMENT_LATE = (
        "the new plan's first segment was not solved within its deadline (controller.replan.first_segment_deadline_s): "
        "the old plan goes on"
    )
    LATE = (
        "the new plan, from the next node, was ready only after the hand would have reached that node: the old "
        "plan goes on"
    )


@dataclass(frozen=True)
class ReplanEvent:
    """One replan: when the state was measured, why, what the planner was told and what it gave."""

    time_s: float  # s, simulated time the replan was decided and the state measured (a node of the executed plan)
    reason: ReplanReason
    mu: float  # the friction coefficient the new plan assumes (the estimate)
    mass: float  # kg, the mass it assumes (the estimate)
    latency_s: float  # s, wall-clock time from the replan's start to the new plan's first segment (or the refusal)
    # s, simulated time the new plan starts, or the old one resumes: from the measured state time_s + latency_s (the
    # hand held), from the next node that node's time (time_s for a refusal: the hand never stopped)
    takes_effect_s: float
    outcome: ReplanOutcome
    status: str  # what a person reads: the planner's status, or why the start or the search was refused
    # why: the search's refusal (trajectotree.refusal; SEARCH_DEADLINE, NO_PLAN) or the start's
    # (trajectotree.start.StartRefusal; START_REFUSED); None otherwise
    refusal: object | None = None
    # s after time_s, when each of the new plan's segments was ready (inf: never; a segment begins no
    # earlier); () when no plan came back
    segment_ready_s: tuple[float, ...] = ()
    compute_s: float = float("nan")  # s, wall-clock time of the whole replan (every segment of a new plan)
    search_s: float = float("nan")  # s, of latency_s, the contact search's (nan: none ran)
    # s, of latency_s, the new plan's first segment's attempts (their programs' builds and IPOPT solves; nan: none ran)
    first_segment_s: float = float("nan")
    first_segment_iterations: int = 0  # IPOPT iterations of those attempts
    # s, simulated time of the state the new plan starts from: the next node's (its planned state) or time_s (the
    # measured state); nan: not recorded
    start_s: float = float("nan")

    @property
    def planned(self) -> bool:
        """A new plan (at least its first segment) was handed to the controller."""
        return self.outcome in (ReplanOutcome.PLANNED, ReplanOutcome.PARTIAL)

    def to_json(self) -> dict:
        return {
            "time_s": self.time_s,
            "reason": self.reason.name.lower(),
            "mu": self.mu,
            "mass": self.mass,
            "latency_s": self.latency_s,
            "takes_effect_s": self.takes_effect_s,
            "planned": self.planned,
            "outcome": self.outcome.name.lower(),
            "status": self.status,
            "refusal": None if self.refusal is None else self.refusal.to_json(),
            "segment_ready_s": [t if math.isfinite(t) else None for t in self.segment_ready_s],
            "compute_s": self.compute_s if math.isfinite(self.compute_s) else None,
            "search_s": self.search_s if math.isfinite(self.search_s) else None,
            "first_segment_s": self.first_segment_s if math.isfinite(self.first_segment_s) else None,
            "first_segment_iterations": self.first_segment_iterations,
            "start_s": self.start_s if math.isfinite(self.start_s) else None,
        }


@dataclass(frozen=True)
class SimResult(SimLog):
    """A SimLog with its tracking metrics (trajectotree.execution.metrics.evaluate): sim.json and sim.npz."""

    abs_error: np.ndarray  # (T, 3) |x - x_plan|, held at its drop-time value after a drop
    mae_x: float  # m, time mean of |x error|
    mae_y: float  # m
    mae_theta: float  # rad
    final_error: tuple[float, float, float]  # (m, m, rad) absolute error at the last sample (not held)
    dropped: bool  # the drop rule fired (trajectotree.execution.metrics.detect_drop)
    drop_time_s: float | None  # s, when it fired
    # (m, m, rad) the absolute error when the drop rule fired, which abs_error and the means hold
    # from then on; None without a drop
    error_at_drop: tuple[float, float, float] | None = None
    replans: tuple[ReplanEvent, ...] = ()  # simulate --replan: each time the closed loop planned again
    diverged_at_s: float | None = None  # s, when the simulation diverged (RunOutcome.DIVERGED); None: it did not
    divergence: str | None = None  # why it counts as diverged, a sentence; None: it did not

    @property
    def within_tolerance(self) -> bool:
        """The run ended within FINAL_THETA_TOLERANCE and FINAL_POSITION_TOLERANCE of the plan's final pose
        (a diverged run has no end: its final_error is the one before it diverged)."""
        return self.divergence is None and ended_within_tolerance(self.final_error)

    @property
    def outcome(self) -> RunOutcome:
        if self.divergence is not None:
            return RunOutcome.DIVERGED
        if self.dropped:
            return RunOutcome.DROPPED
        return RunOutcome.HELD if self.within_tolerance else RunOutcome.OFF_PLAN

    def to_json(self) -> dict:
        """The documented sim.json keys (README, "Executing a plan"), plus the run's length and sample count,
        the controller, the simulated conditions and the closed loop's summary (None: open loop)."""
        return {
            "mae_x": self.mae_x,
            "mae_y": self.mae_y,
            "mae_theta": self.mae_theta,
            "final_error": list(self.final_error),
            "dropped": self.dropped,
            "drop_time_s": self.drop_time_s,
            "error_at_drop": None if self.error_at_drop is None else list(self.error_at_drop),
            "outcome": self.outcome.value,
            "within_tolerance": self.within_tolerance,
            "diverged_at_s": self.diverged_at_s,
            "divergence": self.divergence,
            "sim_time_s": self.sim_time_s,
            "duration_s": float(self.t[-1]),
            "num_samples": int(len(self.t)),
            "controller": self.controller,
            "conditions": self.conditions,
            "closed_loop": None if self.closed_loop is None else self.closed_loop.to_json(self.t),
            "replans": [event.to_json() for event in self.replans],
        }


def ended_within_tolerance(final_error) -> bool:
    """Whether a final error (x m, y m, theta rad) is within FINAL_POSITION_TOLERANCE in position and
    FINAL_THETA_TOLERANCE in orientation."""
    x, y, theta = (float(v) for v in final_error)
    return math.hypot(x, y) <= FINAL_POSITION_TOLERANCE and abs(theta) <= FINAL_THETA_TOLERANCE


def summary_outcome(summary: dict) -> RunOutcome:
    """A run's outcome from its sim.json `summary`; one written before sim.json had "outcome" (no
    divergence test then) from its drop and final error."""
    if "outcome" in summary:
        return RunOutcome(summary["outcome"])
    if summary["dropped"]:
        return RunOutcome.DROPPED
    return RunOutcome.HELD if ended_within_tolerance(summary["final_error"]) else RunOutcome.OFF_PLAN


def outcome_text(summary: dict, noun: str = "box") -> str:
    """How a run ended (sim.json's `summary`), for a person: "box held", "box DROPPED at 4.77 s", "box not
    dropped, but ended 1.100 rad (63 deg) off the plan's final pose (tolerance: 3 deg and 5 mm)", or "the
    simulation DIVERGED at 1.23 s: why"."""
    outcome = summary_outcome(summary)
    if outcome is RunOutcome.DIVERGED:
        return f"the simulation DIVERGED at {summary['diverged_at_s']:.2f} s: {summary['divergence']}"
    if outcome is RunOutcome.DROPPED:
        return f"{noun} DROPPED at {summary['drop_time_s']:.2f} s"
    tolerance = f"{math.degrees(FINAL_THETA_TOLERANCE):g} deg and {1e3 * FINAL_POSITION_TOLERANCE:g} mm"
    if outcome is RunOutcome.HELD:
        return f"{noun} held (ended within {tolerance} of the plan's final pose)"
    x, y, theta = summary["final_error"]
    return (
        f"{noun} not dropped, but ended {abs(theta):.3f} rad ({math.degrees(abs(theta)):.0f} deg) and "
        f"{1e3 * math.hypot(x, y):.1f} mm off the plan's final pose (tolerance: {tolerance})"
    )


# -- in space ------------------------------------------------------------------------------------
# The plan.npz arrays of a hand in space (docs/method.md, "Trajectory optimization in space"), in saving order.
SPACE_TRAJECTORY_ARRAYS = ("t", "x", "v", "q", "tau", "f_W", "p_W_C", "p_W_tip", "p_W_links")
# The rule between knots k and k + 1, h = t_{k+1} - t_k, that the plan was made with and is checked by
# (plan.json "integration"): trapezoidal in the velocities, the forces and the moments.
SPACE_INTEGRATION = (
    "trapezoidal: p[k+1] = p[k] + h (v[k] + v[k+1]) / 2; R[k+1] = exp([h (w[k] + w[k+1]) / 2]x) R[k]; "
    "m (v[k+1] - v[k]) = h (F[k] + F[k+1]) / 2, F = sum_i f_W[i] + m g; "
    "L[k+1] - L[k] = h (T[k] + T[k+1]) / 2, L = R I_B R^T w, T = sum_i (p_W_C[i] - p) x f_W[i]; "
    "x = [qw, qx, qy, qz, px, py, pz] (R from q, p), v = [w, v] in W"
)
# m, a fingertip sphere farther than this from the box carries no force (the rule in space)
SPACE_GAP_TOL = 1e-3
# rad and m, how far the poses may stray from the integration rule's (IPOPT holds its rows to 1e-6)
KINEMATICS_TOL = 1e-5


@dataclass(frozen=True)
class SpaceTrajectory:
    """A plan in space at every knot (the plan.npz arrays of a hand in space)."""

    t: np.ndarray  # (K,) s
    x: np.ndarray  # (K, 7) the object's pose: Drake's floating-body positions [qw, qx, qy, qz, px, py, pz] in W
    v: np.ndarray  # (K, 6) its angular then linear velocity in W (rad/s, m/s)
    q: np.ndarray  # (K, F n) rad, the fingers' joints, finger-major
    tau: np.ndarray  # (K, F n) N m, their motors' torques (quasi-static: J^T f plus the fingers' weight)
    f_W: np.ndarray  # (K, F, 3) N, each fingertip's force ON the object, in W
    p_W_C: np.ndarray  # (K, F, 3) m, where each force acts on the object's surface, in W
    p_W_tip: np.ndarray  # (K, F, 3) m, the fingertip sphere centres in W
    p_W_links: np.ndarray  # (K, F, L, 2, 3) m, the ends of each link's collision capsule axis in W

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in SPACE_TRAJECTORY_ARRAYS}


@dataclass(frozen=True, kw_only=True)  # after PhysicsCheck's fields with defaults
class SpacePhysicsCheck(PhysicsCheck):
    """The check of a plan in space (trajectotree.planning.physics.check_space_physics): the planar
    check's fields, with the gap at SPACE_GAP_TOL, and how far the poses stray from the integration rule."""

    kinematics_rad: float  # max angle between R[k+1] and the rule's exp([h w_mid]x) R[k]
    kinematics_m: float  # max |p[k+1] - p[k] - h v_mid|

    def to_json(self) -> dict:
        return {**super().to_json(), "gap_tol_m": SPACE_GAP_TOL, "kinematics_tol": KINEMATICS_TOL}
