"""The executors' configuration (`ControllerGains`, the YAML section `controller`), grouped by
concern: the paper's eq. 20 fingertip impedance (`impedance`), the object-level grasp controller
and its force QP (`grasp`), the closed loop's contact watch and estimators (`estimators`), its
push reflex (`push_reflex`) and landing reflex (`landing_reflex`), and replanning from the
measured state (`replan`). Each field has its unit and valid range beside it (checks.ranged),
checked by one generic check (checks.check_fields) that names the field, the value and the range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from trajectotree.config.checks import (
    MAX_FORCE,
    MAX_WEIGHT,
    ConfigError,
    Range,
    check_fields,
    flag,
    ranged,
)

# Controller gains: measured on a two-segment plan with a switch (goal 0.35 rad) at the default rate_hz and
# sim.time_step, the discrete loop starts to chatter (joint speeds 5 -> 110 rad/s, the box off its plan) at
# tip_kp 6000-7000 N/m, tip_kd 6-7 N s/m, object_kp 1e5-3e5 s^-2, object_kd 1500-2000 s^-1, kp 1.5e4-2e4 N/m
# and kv 10-13 N s/m; each bound is below that with margin, and the demo's quarter turn holds at each bound.
MAX_TIP_KP = 2000.0  # N/m
MAX_TIP_KD = 5.0  # N s/m, the landing reflex's default tip_kd
MAX_OBJECT_KP = 3e4  # s^-2
MAX_OBJECT_KD = 500.0  # s^-1
MAX_KP = 5000.0  # N/m, eq. 20's fingertip stiffness
MAX_KV = 8.0  # N s/m, eq. 20's fingertip damping


@dataclass(frozen=True)
class ImpedanceGains:
    """Paper eq. 20's fingertip impedance (sim.controller "paper", ImpedanceController), tuned on
    TrajectoTree plans; kv must stay below ~2 m_tip / sim.time_step for the discrete plant to stay stable."""

    kp: float = ranged(400.0, "N/m", 0.0, MAX_KP)  # fingertip position stiffness
    kv: float = ranged(5.0, "N s/m", 0.0, MAX_KV)  # fingertip velocity damping

    def __post_init__(self):
        check_fields(self, "controller.impedance")


@dataclass(frozen=True)
class GraspGains:
    """The object-level GraspController: strong object gains with soft fingertip springs, which hold
    grasps that stiff springs anchored to the measured box lose, and its grasp-force QP."""

    object_kp: float = ranged(2000.0, "s^-2", 0.0, MAX_OBJECT_KP)  # box pose error -> desired acceleration
    object_kd: float = ranged(80.0, "s^-1", 0.0, MAX_OBJECT_KD)  # box velocity error -> desired acceleration
    # fingertip spring to its target on the measured box (x (1 - force budget)), and its damping
    tip_kp: float = ranged(50.0, "N/m", 0.0, MAX_TIP_KP)
    tip_kd: float = ranged(3.0, "N s/m", 0.0, MAX_TIP_KD)
    min_normal_force: float = ranged(0.1, "N", 0.0, MAX_FORCE)  # least push of a finger in contact (the QP)
    # most push of a finger in contact (the QP): room above a plan's squeeze, and near the 1 N m motor limit at the
    # fingers' reach
    max_normal_force: float = ranged(8.0, "N", "min_normal_force", MAX_FORCE, low_open=True)
    # weight of the box-wrench residual (N; torques divided by the box half-diagonal) in the QP, relative to the
    # deviation of the finger forces from the plan's (N), large so that the QP squeezes harder to turn the box back
    # rather than keep the plan's forces
    wrench_weight: float = ranged(1e4, "1", 0.0, MAX_WEIGHT)
    # the QP's friction cones use max(search.friction_safety, this) x scene.mu (0.56 by default, looser than the
    # plan's 0.49), because a sphere sticking to the box rolls where the plan keeps its contact fixed, so executed
    # stances need more friction than the plan's
    friction_safety: float = ranged(0.8, "1", 0.0, 1.0, low_open=True)
    # the QP's cones follow the friction estimate (closed loop) with this time constant (0: at once): a cone that fell
    # from 0.56 to 0.24 in one step moved every finger's force at once and spun the 50 g box off its grasp
    cone_time_constant: float = ranged(0.1, "s", 0.0, 10.0)
    ramp_time: float = ranged(0.1, "s", 0.0, 2.0)  # a switching finger's force budget ramps to 0 after lift-off
    swing_lift: float = ranged(0.008, "m", 0.0, 0.05)  # least fingertip gap mid-swing (lifted where lower)
    contact_distance: float = ranged(
        1e-3, "m", 0.0, 0.02, low_open=True
    )  # a planned fingertip this close is in contact
    # the motors also drive the fingers' own links (mass matrix, Coriolis, joint damping). Off by default: on
    # Drake's gripper (with min_normal_force 1.5 N) it ends 10 of 12 goals within 3e-4 rad but drops the other 2
    # (docs/results.md).
    hand_dynamics: bool = flag(False)
    # in space, a moving fingertip tracks its path as a critically damped second-order system of this bandwidth
    # through the finger's own inertia (execution.space_control): a spring of tip_kp on a fingerpro4 finger (its
    # links 0.6 kg) lagged 10-20 mm behind a lift-off and pushed the tip along the face where it pulled it up
    swing_bandwidth: float = ranged(30.0, "rad/s", 0.0, 100.0)

    def __post_init__(self):
        check_fields(self, "controller.grasp")


@dataclass(frozen=True)
class EstimatorGains:
    """The closed loop's contact watch and its friction and mass estimates, which the grasp QP then
    uses (trajectotree.execution.closed_loop). Unused in open loop."""

    # a contact whose tangential velocity at the contact point exceeds this slides
    slip_speed: float = ranged(0.005, "m/s", 0.0, 1.0, low_open=True)
    # a contact pushing less is not watched for slip (touch-downs, lift-offs); at most grasp.max_normal_force
    slip_min_force: float = ranged(0.05, "N", 0.0, MAX_FORCE)
    slip_confirm_time: float = ranged(0.01, "s", 0.0, 1.0)  # a contact must slide this long before its ratio counts
    # and push at least this hard (at most grasp.max_normal_force): in Drake's lagged contact model lighter contacts
    # slide below the world's friction (8 nominal runs at mu 0.7: steady slides under 0.4 N read 0.32-0.68, above it
    # 0.71)
    friction_evidence_force: float = ranged(0.4, "N", 0.0, MAX_FORCE)
    # and only while the box is this close to the plan (position, and theta error x the box's circumradius): slides
    # of a box already off the plan read 0.26-0.38 in worlds of 0.3-0.4 (8 plans), the first ones 0.30-0.40
    friction_evidence_error: float = ranged(0.005, "m", 0.0, 1.0, low_open=True)
    # the friction estimate (only ever lowered, by slides) never goes below this
    friction_floor: float = ranged(0.2, "1", 0.0, 1.0, low_open=True)
    # the fingers' vertical force measures the mass while |box accel| < this
    mass_accel_max: float = ranged(0.5, "m/s^2", 0.0, 100.0, low_open=True)
    mass_time_constant: float = ranged(0.2, "s", 0.0, 100.0, low_open=True)  # low-pass time constant of the mass
    # the mass estimate / planned mass stays within this (low, high)
    mass_estimate_range: tuple[float, float] = ranged(
        (0.25, 4.0), (Range("1 (low)", 0.0, 1.0, low_open=True), Range("1 (high)", 1.0, 100.0))
    )

    def __post_init__(self):
        check_fields(self, "controller.estimators")


@dataclass(frozen=True)
class PushReflexGains:
    """The closed loop's push reflex (PushReflex and the grasp QP while it is on)."""

    # a force on the box that neither the fingers' measured forces nor gravity explain (m a - f - m g) starts the
    # reflex when it lasts confirm_time
    force: float = ranged(1.0, "N", 0.0, MAX_FORCE, low_open=True)
    confirm_time: float = ranged(0.004, "s", 0.0, 1.0)
    # during the reflex the grasp QP's target push of each holding finger rises to this (<= grasp.max_normal_force):
    # a target, not a bound, for a finger whose face turns along the push would push the box with it (a bound of 2 N
    # cost a 3-finger grasp 1.3 N of its 3.6 N against a +x push, and the box)
    squeeze: float = ranged(2.0, "N", 0.0, MAX_FORCE)
    gain: float = ranged(4.0, "1", 1.0, 100.0)  # grasp.object_kp x this during the reflex (object_kd x its root)
    hold: float = ranged(0.2, "s", 0.0, 10.0)  # the reflex stays on this long after its trigger ends
    release: float = ranged(0.2, "s", 0.0, 10.0)  # then fades back to the plan's gains and squeeze over this
    # the fraction of the measured disturbance (PushReflex's) that the desired box wrench cancels at once: the
    # feedback alone answered a 3 N push only after the box had moved and turned
    disturbance_feedforward: float = ranged(1.0, "1", 0.0, 1.0)
    # the grasp QP's weight on the box torque residual x this during the reflex: a grasp short of force spends it
    # along the push rather than let the box turn
    torque_weight: float = ranged(10.0, "1", 1.0, 1e4)
    # the grasp QP's cones at max(grasp.friction_safety, this) x the friction estimate during the reflex: at 0.8 a
    # three-finger grasp held at most 2.9 N against +x (3.8 N at 1.0), short of a 3 N push
    friction_safety: float = ranged(1.0, "1", 0.0, 1.0, low_open=True)

    def __post_init__(self):
        check_fields(self, "controller.push_reflex")


@dataclass(frozen=True)
class LandingReflexGains:
    """The closed loop's landing reflex: while a push is on or the friction estimate is friction_drop
    below the plan's, a swinging finger runs its planned box-frame path speedup x as fast to its next
    planned landing (tip spring tip_kp, tip_kd), and holds there until the plan gets there: the grasp
    gets all its fingers."""

    speedup: float = ranged(20.0, "1", 1.0, 100.0)  # how much faster a swing runs (1: no landing reflex)
    friction_drop: float = ranged(0.05, "1", 0.0, 1.0, low_open=True)
    # s of the plan, the end of the path to the landing, run approach_speedup x
    approach_time: float = ranged(0.1, "s", 0.0, 2.0)
    approach_speedup: float = ranged(4.0, "1", 1.0, 100.0)
    lag: float = ranged(0.02, "m", 0.0, 0.1, low_open=True)  # the path waits while the fingertip is this far behind
    # the same fingertip's spring as grasp.tip_kp, tip_kd, so it has their bounds
    tip_kp: float = ranged(400.0, "N/m", 0.0, MAX_TIP_KP)
    tip_kd: float = ranged(5.0, "N s/m", 0.0, MAX_TIP_KD)

    def __post_init__(self):
        check_fields(self, "controller.landing_reflex")


@dataclass(frozen=True)
class ReplanConfig:
    """When the closed loop plans again (simulate --replan), and from where: checked at the plan's nodes,
    where every finger holds the object at rest; the new plan starts at the next node's planned state,
    or at the measured state with the hand holding (trajectotree.execution.replan)."""

    # tracking error in orientation past which the plan no longer holds (~3 deg)
    theta_error: float = ranged(0.05, "rad", 0.0, math.pi, low_open=True)
    position_error: float = ranged(0.005, "m", 0.0, 0.05, low_open=True)  # the same in position: 10x a tracked plan's
    # the friction estimate this far below the plan's scene.mu: its stances may slip
    friction_drop: float = ranged(0.05, "1", 0.0, 1.0, low_open=True)
    # a mass estimate this far (relative) from the plan's: its forces are wrong
    mass_change: float = ranged(0.2, "1", 0.0, 10.0, low_open=True)
    # per run, so a task the hand cannot do ends rather than replans forever
    max_replans: int = ranged(4, "replans", 0, 100, integer=True)
    # A replan from the next node (the hand going on along its plan meanwhile) must be ready by the time the hand
    # reaches that node: its search gets that time less this, kept for the first segment's IPOPT (0.28 s median,
    # 0.56 s p95 on the 60 paper goals, 2 loaded cores), and the first segment that time.
    first_segment_reserve_s: float = ranged(0.5, "s", 0.0, 60.0, low_open=True)
    # a tracking error or a lost contact (the plan's next node may be wrong) plans from the measured state, the hand
    # holding while the planner runs, rather than from the next node as a changed estimate does
    measured_start_on_error: bool = flag(False)
    # A replan's wall-clock budget for its contact search (its search.time_budget_s; from the next node at most
    # this too, so the latency stays bounded); a search without a plan by then is refused (the old plan goes on).
    # 0.25 s and the first segment's 0.37 s keep a replan's latency p95 within 0.4 s (issue 35): on 20 paper goals
    # at friction 0.4 the same 5 drops as at 0.5 s and 1.0 s, 26 planned replans instead of 32 (a search that needs
    # more than 0.25 s rarely finds a plan: docs/measurements.md, "Replanning latency: where a replan's time goes").
    search_deadline_s: float = ranged(0.25, "s", 0.0, 60.0, low_open=True)
    # and its first segment must be solved (all its attempts) this long after the state was measured, the search
    # included, or it is refused too: the hand holds no longer than about this, less than a segment lasts
    # (cito.knots_per_segment x cito.dt, 1.2 s); the first segment's IPOPT takes 0.12-0.3 s (15 iterations)
    first_segment_deadline_s: float = ranged(0.37, "s", 0.0, 600.0, low_open=True)
    # In space a plan (its search, then every segment at once) takes 5-30 s, far more than a segment lasts (1 s): a
    # replan there always plans from the measured state, the hand holding, its search given this (wall clock) ...
    space_search_deadline_s: float = ranged(30.0, "s", 0.0, 600.0, low_open=True)
    # ... and the whole new plan this long after the state was measured, the search included, or it is refused
    space_plan_deadline_s: float = ranged(60.0, "s", 0.0, 600.0, low_open=True)

    def __post_init__(self):
        check_fields(self, "controller.replan")


@dataclass(frozen=True)
class ControllerGains:
    """Both executors' settings (the same for every method), by concern."""

    rate_hz: float = ranged(500.0, "Hz", 10.0, 10000.0)  # control and estimation rate (held between updates)
    impedance: ImpedanceGains = field(default_factory=ImpedanceGains)
    grasp: GraspGains = field(default_factory=GraspGains)
    estimators: EstimatorGains = field(default_factory=EstimatorGains)
    push_reflex: PushReflexGains = field(default_factory=PushReflexGains)
    landing_reflex: LandingReflexGains = field(default_factory=LandingReflexGains)
    replan: ReplanConfig = field(default_factory=ReplanConfig)

    def __post_init__(self):
        check_fields(self, "controller")
        # forces bounded by the grasp QP's largest push, which is another group's
        most = Range("N", 0.0, self.grasp.max_normal_force)
        most.check(self, "controller.estimators.slip_min_force", self.estimators.slip_min_force)
        most.check(self, "controller.estimators.friction_evidence_force", self.estimators.friction_evidence_force)
        most.check(self, "controller.push_reflex.squeeze", self.push_reflex.squeeze)


CONTROLLERS = ("grasp", "paper")  # sim.controller values: object-level grasp control, paper eq. 20


def check_controller(value: str, name: str = "controller") -> str:
    """`value` if it names an executor; ConfigError naming `name` (the field or option) otherwise."""
    if value not in CONTROLLERS:
        raise ConfigError(field=name, value=value, problem="is not a controller", choices=CONTROLLERS)
    return value


# The controller section's flat keys before the groups above (plan.json files written until then): old key ->
# (group, field), so that those plans still execute with the settings they were planned with.
FLAT_KEYS = {
    **{name: ("impedance", name) for name in ("kp", "kv")},
    **{
        name: ("grasp", name)
        for name in (
            "object_kp",
            "object_kd",
            "tip_kp",
            "tip_kd",
            "min_normal_force",
            "max_normal_force",
            "wrench_weight",
            "friction_safety",
            "cone_time_constant",
            "ramp_time",
            "swing_lift",
            "contact_distance",
            "hand_dynamics",
        )
    },
    **{
        name: ("estimators", name)
        for name in (
            "slip_speed",
            "slip_min_force",
            "slip_confirm_time",
            "friction_evidence_force",
            "friction_evidence_error",
            "friction_floor",
            "mass_accel_max",
            "mass_time_constant",
            "mass_estimate_range",
        )
    },
    **{
        f"reflex_{name}": ("push_reflex", name)
        for name in ("force", "confirm_time", "squeeze", "gain", "hold", "release", "torque_weight", "friction_safety")
    },
    "disturbance_feedforward": ("push_reflex", "disturbance_feedforward"),
    **{
        f"land_{name}": ("landing_reflex", name)
        for name in ("speedup", "friction_drop", "approach_time", "approach_speedup", "lag", "tip_kp", "tip_kd")
    },
}


def nest_flat_keys(controller: dict) -> dict:
    """A controller section with the flat keys of FLAT_KEYS moved into their groups (others unchanged)."""
    nested = {k: v for k, v in controller.items() if k not in FLAT_KEYS}
    for key, value in controller.items():
        if key in FLAT_KEYS:
            group, name = FLAT_KEYS[key]
            nested.setdefault(group, {})[name] = value
    return nested
