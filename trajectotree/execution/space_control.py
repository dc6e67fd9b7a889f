"""The object-level grasp controller in space (issue 37): the planar GraspController's design
(trajectotree.execution.control) with 6-D wrenches, for a hand in space (scene.spatial.SpaceScene) and its cube
on a quaternion floating joint.

SpaceGraspController, periodic at ControllerGains.rate_hz, reads the measured state of the cube and the hand and
  1. asks for the cube wrench w = w_plan + [m (Kp e_p + Kd e_v); I_W (Kp e_R + Kd e_w)]: w_plan the plan's
     feed-forward (the sum of its fingertip forces f_W and of their moments about the cube's centre), e_R the
     orientation error in W from the quaternions (the log map of R_plan^T R: no Euler angles), I_W = R I_B R^T;
  2. splits w over the fingertips' 3-D forces with a QP (SpaceGraspForceQp, Clarabel): min wrench_weight
     |G lambda - w|^2_W + |lambda - lambda_plan|^2 over lambda = (lambda_n, lambda_1, lambda_2) per finger, inside
     the pyramids inscribed in the friction cones at the controller's friction (control_friction: a safety
     fraction of the plan's), lambda_n in s [min, max] N (s the force budget, 0 for the moving finger, ramped
     around its lift-off and landing as in the plane) and within the motors: |J_C^T f + rest| <= tau_max;
  3. commands tau = J_C^T f + J^T ((1 - s) K_t (p_target - p) + D (v_target - v)) + g_hand: J_C the Jacobian of
     the contact point (the sphere's surface, tip_radius from its centre along -n), the fingertip targets the
     plan's, in the plan's cube frame, mapped through the MEASURED cube pose (the moving finger follows its planned
     path on that impedance), g_hand the plant's gravity torques on the links.
Where it differs from the plane: the orientation error (a rotation vector from quaternions, not an angle
difference), the feed-forward (the plan's contact wrench itself, where the plane uses M a_plan + m g: in space
the plan's forces already carry R I_B R^T and its gyroscopic term), the cones (pyramids: scene.statics'
cone_rows_3d, not two rows), the contact normals (the cube's face nearest each measured fingertip:
geometry.box_face_normals) and the kinematics (the plant's Jacobians; the plane has closed forms for two links).
Shared: the tangent basis, the grasp matrix and the torque rows (scene.statics), the force-budget ramps
(reference.swing_intervals and swing_profile), the gains and the friction (config.controller, control_friction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions
from pydrake.systems.framework import EventStatus, LeafSystem

from trajectotree.config import Config, ControllerGains
from trajectotree.execution.control import EstimatePorts, Estimates
from trajectotree.execution.in_effect import PlanInEffect, declare_plan_input
from trajectotree.execution.reference import swing_intervals, swing_profile
from trajectotree.geometry import (
    box_face_normals,
    box_outward_directions,
    box_signed_distances,
    matrix_quaternions,
    quaternion_error_W,
    quaternion_matrices,
    so3_exp,
)
from trajectotree.scene.spatial import SpaceScene
from trajectotree.scene.statics import (
    cone_rows_3d,
    contact_torque_rows,
    grasp_matrix_3d_W,
    tangent_basis,
    wrenches_W,
)

CONE_FACETS = 8  # the QP's pyramid per cone, as the planner's (cito.spatial.PYRAMID_EDGES)
SINGULAR_DAMPING = 0.01  # m, of the moving fingertips' damped least-squares accelerations (a tenth of a link)
BOX_STATE_SIZE = 13  # the quaternion floating joint's [qw, qx, qy, qz, px, py, pz, w_W (3), v_W (3)]


@dataclass(frozen=True)
class SpaceReference:
    """A plan in space as the execution follows it: its plan.npz arrays (results.SpaceTrajectory's names), t
    starting at 0."""

    t: np.ndarray  # (K,) s
    x: np.ndarray  # (K, 7) [qw, qx, qy, qz, px, py, pz] in W
    v: np.ndarray  # (K, 6) [w_W, v_W] rad/s, m/s
    q: np.ndarray  # (K, F n) rad, finger-major
    f_W: np.ndarray  # (K, F, 3) N, each fingertip's force on the cube, in W
    p_W_C: np.ndarray  # (K, F, 3) m, where it acts
    p_W_tip: np.ndarray  # (K, F, 3) m, the fingertip sphere centres

    @classmethod
    def from_arrays(cls, arrays) -> SpaceReference:
        a = {name: np.asarray(arrays[name], dtype=float) for name in ("t", "x", "v", "q", "f_W", "p_W_C", "p_W_tip")}
        a["t"] = a["t"] - a["t"][0]
        return cls(**a)

    @classmethod
    def held(cls, pose, q, p_W_tip, p_W_C, f_W, duration: float) -> SpaceReference:
        """A reference that holds the cube at rest at `pose` (7,) for `duration` s, the joints at q (F n,), each
        fingertip centre at p_W_tip (F, 3) pushing with f_W (F, 3) at p_W_C (F, 3) (a static grasp, for tests)."""

        def two(a):
            return np.stack([np.asarray(a, dtype=float)] * 2)

        return cls(
            t=np.array([0.0, duration]),
            x=two(pose),
            v=np.zeros((2, 6)),
            q=two(q),
            f_W=two(f_W),
            p_W_C=two(p_W_C),
            p_W_tip=two(p_W_tip),
        )

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def num_fingers(self) -> int:
        return self.f_W.shape[1]

    def motion_at(self, times) -> dict[str, np.ndarray]:
        """The cube's planned motion at `times` (T,) by the plan's own rule between knots (results.SPACE_INTEGRATION:
        the velocities linear, so the accelerations constant within an interval, the orientation turned by the
        integral of w), held at rest after the end: `x` (T, 7), `w`, `v`, `alpha`, `a` (T, 3 each, in W)."""
        times = np.asarray(times, dtype=float)
        t, K = self.t, len(self.t)
        k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, K - 2)
        h = t[k + 1] - t[k]
        s = np.clip(times - t[k], 0.0, h)[:, None]
        w0, w1, v0, v1 = self.v[k, :3], self.v[k + 1, :3], self.v[k, 3:], self.v[k + 1, 3:]
        alpha, a = (w1 - w0) / h[:, None], (v1 - v0) / h[:, None]
        R = so3_exp(s * w0 + 0.5 * s**2 * alpha) @ quaternion_matrices(self.x[k, :4])
        p = self.x[k, 4:] + s * v0 + 0.5 * s**2 * a
        w, v = w0 + s * alpha, v0 + s * a
        after = times >= t[-1]
        R[after], p[after] = quaternion_matrices(self.x[-1, :4]), self.x[-1, 4:]
        for value in (w, v, alpha, a):
            value[after] = 0.0
        quat = matrix_quaternions(R)
        quat *= np.where(np.sum(quat * self.x[k, :4], axis=-1, keepdims=True) < 0, -1.0, 1.0)  # the plan's sign
        return {"x": np.hstack([quat, p]), "w": w, "v": v, "alpha": alpha, "a": a}

    def pose_at(self, times) -> np.ndarray:
        """(T, 7) the planned pose at `times` (motion_at)."""
        return self.motion_at(times)["x"]

    def forces_at(self, times) -> np.ndarray:
        """(T, F, 3) the planned fingertip forces, linear between knots, held after the end."""
        return _linear(self.t, self.f_W, times)

    def touching(self, tip_radius: float, contact_distance: float) -> np.ndarray:
        """(K, F) bool: the fingertips within `contact_distance` of their contact points' surface (the plan's gap)."""
        gap = np.linalg.norm(self.p_W_tip - self.p_W_C, axis=-1) - tip_radius
        return gap <= contact_distance


def _linear(t, values, times) -> np.ndarray:
    """values (K, ...) at knots t, linear in between and held outside: (T, ...)."""
    flat = values.reshape(len(t), -1)
    out = np.stack([np.interp(times, t, flat[:, j]) for j in range(flat.shape[1])], axis=1)
    return out.reshape((len(times),) + values.shape[1:])


PATH_SAMPLES = 200  # per swing: the lifted path's samples whose length the finger's travel follows


@dataclass(frozen=True)
class SwingLift:
    """Lifts a swinging fingertip centre off a cube of half-sizes `half` (3,) m: to at least height x lift m of gap
    (the sphere of tip_radius m to the surface), away from the nearest surface point, as the plane's
    reference.grasp_schedule; the plan keeps its fingertips clear at the knots alone."""

    half: tuple[float, float, float]
    tip_radius: float
    lift: float

    def __call__(self, p_B, height) -> np.ndarray:
        """(..., 3) the points p_B (..., 3) lifted to `height` (...) in [0, 1] (nan: not lifted)."""
        gap = box_signed_distances(self.half, p_B) - self.tip_radius
        extra = np.nan_to_num(np.maximum(self.lift * np.asarray(height) - gap, 0.0))
        return p_B + extra[..., None] * box_outward_directions(self.half, p_B)


@dataclass(frozen=True)
class SwingTiming:
    """One finger's swings on the control grid (T,), for swing_timing."""

    scale: np.ndarray  # (T,) its force budget: 1 holding, 0 moving
    p_B: np.ndarray  # (T, 3) m, its fingertip centre's target in the planned cube frame
    lifting: np.ndarray  # (T,) bool, in the lift-off hold of a swing
    lift_off_knot: np.ndarray  # (T,) int, the knot of the swing's lift-off in its lift-off hold, -1 elsewhere
    carry: np.ndarray  # (T,) 1 -> 0 from its lift-off hold to its landing hold, 0 outside swings


def _minimum_jerk(u) -> np.ndarray:
    """The minimum-jerk rest-to-rest profile 0 -> 1 at u in [0, 1]."""
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def swing_timing(times, t_knots, in_contact, p_knots, ramp_time: float, lift: SwingLift) -> SwingTiming:
    """A finger's SwingTiming at `times` (T,) for the plan's knots t_knots (K,), whether it touches at each (K,)
    bool and where its tip is (K, 3) m in B. A swing (lo, hi) has five stages of `hold` s (ramp_time, at most a
    sixth of the swing) but the third: its force budget ramps out on its lift-off point (the lift-off hold); it
    rises straight off it; it travels the plan's path through its knots, lifted fully (`lift`: the edges that
    seed-0 goal 1's path crosses lie near its ends), at a minimum-jerk rate along the lifted path's length; it
    descends straight onto its landing point; its budget ramps in there. Each move is from rest to rest: the plan
    fixes a free finger at its knots only, and its own time law moved a fingertip 23 mm in the 0.1 s after
    lift-off (seed-0 goal 1), which a fingerpro4 finger (0.6 kg of links, 0.396 N m motors) lagged, cutting the
    cube's edge. It loads and unloads on the cube alone: a budget that rose while the finger descended had the
    QP push a finger still in the air, which struck the cube at 0.3 m/s (seed-0 goal 3's second landing, 10 deg
    off). In a swing without a lift-off or a landing (the plan's ends): its own time, the budget as
    reference.swing_profile."""
    times = np.asarray(times, dtype=float)
    intervals = swing_intervals(t_knots, in_contact)
    scale, phase = swing_profile(times, [iv for iv in intervals if not np.all(np.isfinite(iv))], ramp_time)
    p_B = lift(_linear(t_knots, p_knots, times), np.sin(np.pi * phase))
    lifting, lift_off_knot, carry = np.zeros(len(times), dtype=bool), np.full(len(times), -1), np.zeros(len(times))
    for lo, hi in intervals:
        if not np.isfinite(lo) or not np.isfinite(hi):
            continue
        hold = min(ramp_time, (hi - lo) / 6)
        scale = np.minimum(scale, swing_profile(times, [(lo, hi)], hold)[0])
        u = np.linspace(0.0, 1.0, PATH_SAMPLES + 1)
        path = lift(_linear(t_knots, p_knots, lo + u * (hi - lo)), np.ones_like(u))
        length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        inside = (times > lo) & (times < hi)
        tau = np.clip((times[inside] - lo - 2 * hold) / (hi - lo - 4 * hold), 0.0, 1.0)
        covered = _minimum_jerk(tau)
        at = np.interp(covered * length[-1], length, u) if length[-1] > 1e-9 else covered
        travel = np.column_stack([np.interp(at, u, path[:, c]) for c in range(3)])
        ends = np.where((tau <= 0.0)[:, None], *_linear(t_knots, p_knots, np.array([lo, hi]))[:, None])
        edge = np.minimum(times[inside] - lo, hi - times[inside])  # s from the nearer end
        height = np.clip(edge / hold - 1.0, 0.0, 1.0) if hold > 0 else np.ones(len(tau))
        rise = lift(ends, _minimum_jerk(height))  # on the plan's point in the holds, straight off or onto it
        p_B[inside] = np.where(((tau > 0.0) & (tau < 1.0))[:, None], travel, rise)
        carry[inside] = 1.0 - at
        holding = inside & (times < lo + hold)
        lifting |= holding
        lift_off_knot[holding] = int(np.argmin(np.abs(t_knots - lo)))
    return SwingTiming(scale, p_B, lifting, lift_off_knot, carry)


@dataclass(frozen=True)
class SpaceSchedule:
    """What the SpaceGraspController tracks, sampled at its control times n * period and held after the plan."""

    period: float  # s
    x: np.ndarray  # (N, 7) the planned pose
    w: np.ndarray  # (N, 3) rad/s, its angular velocity in W
    v: np.ndarray  # (N, 3) m/s, its velocity in W
    wrench: np.ndarray  # (N, 6) [N; N m] the plan's contact wrench on the cube about its centre, in W
    p_BF: np.ndarray  # (N, F, 3) m, the fingertip centres in the planned cube frame B
    v_BF: np.ndarray  # (N, F, 3) m/s, their rates in B
    a_BF: np.ndarray  # (N, F, 3) m/s^2, their accelerations in B
    f_B: np.ndarray  # (N, F, 3) N, the planned fingertip forces in B
    force_scale: np.ndarray  # (N, F) 1 holding, 0 moving, ramped over ramp_time around lift-off and landing
    lifting: np.ndarray  # (N, F) bool: in the lift-off hold of a swing (swing_timing)
    unload_force: np.ndarray  # (N, F) N, in the lift-off hold the plan's force at lift-off, inf elsewhere
    carry: np.ndarray  # (N, F) the share of its lift-off offset a swinging finger's target keeps (swing_timing)

    def index(self, t: float) -> int:
        return min(int(round(t / self.period)), len(self.x) - 1)


def space_schedule(
    reference: SpaceReference,
    *,
    tip_radius: float,
    period: float,
    duration: float,
    ramp_time: float,
    contact_distance: float,
    half,
    swing_lift: float,
) -> SpaceSchedule:
    """The SpaceSchedule of `reference` on the control grid 0, period, ... <= duration, for a cube of half-sizes
    `half` (3,) m: each finger's swings as swing_timing, lifted to at least swing_lift sin(pi phase) m off the
    cube (SwingLift: the path between the plan's knots may cut through it, 5 mm into an edge on seed-0 goal 1's
    first lift-off)."""
    t = reference.t
    times = np.arange(int(np.floor(duration / period + 1e-9)) + 1) * period
    motion = reference.motion_at(times)
    R_knots = quaternion_matrices(reference.x[:, :4])  # (K, 3, 3)
    p_knots = reference.x[:, None, 4:]
    p_BF_knots = np.einsum("kji,kfj->kfi", R_knots, reference.p_W_tip - p_knots)
    f_B_knots = np.einsum("kji,kfj->kfi", R_knots, reference.f_W)
    wrench_knots = wrenches_W(reference.p_W_C - p_knots, reference.f_W).sum(axis=1)  # (K, 6)
    touching = reference.touching(tip_radius, contact_distance)
    F = reference.num_fingers
    lift = SwingLift(tuple(float(h) for h in half), tip_radius, swing_lift)
    swings = [swing_timing(times, t, touching[:, i], p_BF_knots[:, i], ramp_time, lift) for i in range(F)]
    scale, lifting, carry = (
        np.column_stack([getattr(w, name) for w in swings]) for name in ("scale", "lifting", "carry")
    )
    p_BF = np.stack([w.p_B for w in swings], axis=1)
    plan_force = np.linalg.norm(reference.f_W, axis=-1)  # (K, F)
    unload = np.column_stack(
        [
            np.where(w.lift_off_knot >= 0, plan_force[np.maximum(w.lift_off_knot, 0), i], np.inf)
            for i, w in enumerate(swings)
        ]
    )
    v_BF = np.gradient(p_BF, times, axis=0) if len(times) > 1 else np.zeros_like(p_BF)
    a_BF = np.gradient(v_BF, times, axis=0) if len(times) > 1 else np.zeros_like(p_BF)
    return SpaceSchedule(
        period=period,
        x=motion["x"],
        w=motion["w"],
        v=motion["v"],
        wrench=_linear(t, wrench_knots, times),
        p_BF=p_BF,
        v_BF=v_BF,
        a_BF=a_BF,
        f_B=_linear(t, f_B_knots, times),
        force_scale=scale,
        lifting=lifting,
        unload_force=unload,
        carry=carry,
    )


def space_plan_in_effect(
    reference: SpaceReference, config: Config, scene: SpaceScene, *, mu_assumed: float | None = None, version: int = 0
) -> PlanInEffect:
    """The PlanInEffect of a plan in space: its reference and the controller's schedule of it, at the controller's
    rate to the run's end (the plan, then config.sim.settle_time of hold), assuming friction `mu_assumed` (None:
    config.scene.mu, the plan's), the `version`-th plan of the run (a replan's new plans: 1, 2, ...)."""
    gains = config.controller
    schedule = space_schedule(
        reference,
        tip_radius=scene.tip_radius,
        period=1.0 / gains.rate_hz,
        duration=reference.duration + config.sim.settle_time,
        ramp_time=gains.grasp.ramp_time,
        contact_distance=gains.grasp.contact_distance,
        half=scene.object.half,
        swing_lift=gains.grasp.swing_lift,
    )
    return PlanInEffect(reference, schedule, config.scene.mu if mu_assumed is None else mu_assumed, version)


class SpaceGraspForceQp:
    """min wrench_weight |G lambda - w|^2_W + |lambda - lambda_plan|^2 over lambda = (lambda_n, lambda_1, lambda_2)
    per finger (G (6, 3F): scene.statics.grasp_matrix_3d_W), lambda_n in [lo, hi], inside the pyramids inscribed in
    the friction cones at `mu` (cone_rows_3d) and within the motors (contact_torque_rows, each solve's); W weighs the
    torques by 1 / torque_length^2. Built once; each solve updates the cost, the bounds and the torque rows. Solved
    by Clarabel, as the planar closed loop's QP with its torque rows (control.GraspForceQp: OSQP's ADMM needed
    hundreds of iterations on such rows)."""

    def __init__(self, mu: float, torque_length: float, wrench_weight: float, *, num_fingers: int, num_joints: int):
        n = 3 * num_fingers
        self._num_fingers, self._mu = num_fingers, mu
        self._prog = MathematicalProgram()
        z = self._prog.NewContinuousVariables(n, "lambda")  # finger-major (n, 1, 2)
        self._cost = self._prog.AddQuadraticCost(np.eye(n), np.zeros(n), z, is_convex=True)
        self._bounds = self._prog.AddBoundingBoxConstraint(np.zeros(n), np.zeros(n), z)
        rows = cone_rows_3d(mu, num_fingers, CONE_FACETS)
        self._cone = self._prog.AddLinearConstraint(rows, np.full(len(rows), -np.inf), np.zeros(len(rows)), z)
        m = num_fingers * num_joints
        self._torque = self._prog.AddLinearConstraint(np.zeros((m, n)), np.full(m, -np.inf), np.full(m, np.inf), z)
        self._W = wrench_weight * np.diag([1.0, 1.0, 1.0] + [1.0 / torque_length**2] * 3)
        self._solver, self._options = ClarabelSolver(), SolverOptions()

    def set_friction(self, mu: float) -> None:
        """The cones' friction coefficient from the next solve on."""
        if mu != self._mu:
            rows = cone_rows_3d(mu, self._num_fingers, CONE_FACETS)
            self._cone.evaluator().UpdateCoefficients(rows, np.full(len(rows), -np.inf), np.zeros(len(rows)))
            self._mu = mu

    def solve(self, G, wrench, lambda_plan, lo, hi, torque, torque_weight: float = 1.0) -> np.ndarray:
        """lambda (F, 3) for G (6, 3F), the wrench (6,), the plan's lambda (F, 3), the normal-force bounds lo, hi
        (F,) and torque = (A, lower, upper) (contact_torque_rows); `torque_weight` multiplies the weight of the
        wrench's torque residual. Falls back to the plan's forces, clipped to the bounds and the cones' circle, if
        the solver fails."""
        z_plan = np.ravel(lambda_plan)
        GtW = G.T @ (self._W * np.repeat([1.0, torque_weight], 3))  # W diagonal: its torque columns scaled
        self._cost.evaluator().UpdateCoefficients(2.0 * (GtW @ G + np.eye(len(z_plan))), -2.0 * (GtW @ wrench + z_plan))
        t_max = self._mu * np.asarray(hi)
        self._bounds.evaluator().set_bounds(
            np.column_stack([lo, -t_max, -t_max]).ravel(), np.column_stack([hi, t_max, t_max]).ravel()
        )
        self._torque.evaluator().UpdateCoefficients(*torque)
        result = self._solver.Solve(self._prog, None, self._options)
        if result.is_success():
            return result.get_x_val().reshape(self._num_fingers, 3)  # z is the program's only variable
        normal = np.clip(lambda_plan[:, 0], lo, hi)
        tangential = lambda_plan[:, 1:]
        size = np.maximum(np.linalg.norm(tangential, axis=1), 1e-12)
        return np.column_stack([normal, tangential * np.minimum(1.0, self._mu * normal / size)[:, None]])


class SpaceGraspController(LeafSystem):
    """Object-level grasp control of a planned cube motion in space, open loop (the module doc). Input ports:
    `box_state` (13: the cube's quaternion floating joint [qw, qx, qy, qz, px m, py m, pz m, w_W rad/s (3),
    v_W m/s (3)], the plant's state of the cube's model instance), `hand_state` (2 F n: the hand's [q rad; v
    rad/s], finger-major) and `plan` (a PlanInEffect whose schedule is a SpaceSchedule). Output port `actuation`
    (F n joint torques, N m, the plant's actuation order), updated every 1 / gains.rate_hz s and held in between.
    `scene` is the plan's (its cube's mass and size, the hand's kinematics and weight from its own plant, not the
    simulated one's); `mu` the friction of the QP's cones."""

    def __init__(self, scene: SpaceScene, gains: ControllerGains, *, mu: float):
        super().__init__()
        self.gains = gains
        plant = scene.plant
        self._plant, self._context = plant, plant.CreateDefaultContext()
        self._hand = scene.hand
        self._tips = [scene.tip_frame(i) for i in range(scene.num_fingers)]
        self._tip_radius, self._half = scene.tip_radius, scene.object.half
        self._mass = scene.object.mass
        self.planned = Estimates(mu=mu, mass=scene.object.mass, reflex=0.0, disturbance=np.zeros(3))
        self._friction_safety = mu / scene.object.mu  # the cones' fraction of the friction the plan assumed
        self._I_B = scene.object.inertia
        self._tau_max = scene.tau_max
        self._num_fingers, self._joints_per_finger = scene.tau_max.shape
        joints = [plant.GetJointByName(n, scene.hand) for f in scene.hand_file.fingers for n in f.joints]
        self._hand_v = np.array([j.velocity_start() for j in joints])  # finger-major, in the plant's velocities
        hand_q = plant.GetPositionsFromArray(scene.hand, np.arange(plant.num_positions())).astype(int)
        if not np.array_equal(hand_q, scene.hand_q_indices):
            raise ValueError(f"hand {scene.hand_file.source}: its model's joints are not in its description's order")
        B = plant.MakeActuationMatrix()  # (nv, nu), a selection
        self._u_from_tau = B[self._hand_v].T
        self._qp = SpaceGraspForceQp(
            mu,
            float(np.linalg.norm(scene.object.half)),  # m, the torque length: the cube's half diagonal
            gains.grasp.wrench_weight,
            num_fingers=self._num_fingers,
            num_joints=self._joints_per_finger,
        )
        nq = len(hand_q)
        self.box_state_port = self.DeclareVectorInputPort("box_state", BOX_STATE_SIZE)
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * nq)
        self.plan_port = declare_plan_input(self)
        state = self.DeclareDiscreteState(B.shape[1])
        self._offset_state = self.DeclareDiscreteState(3 * self._num_fingers)  # swing_offsets, m in B
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self.UpdateActuation)
        self.DeclareInitializationDiscreteUpdateEvent(self.UpdateActuation)
        self.actuation_port = self.DeclareStateOutputPort("actuation", state)

    def estimates(self, context) -> Estimates:
        """What the controller assumes now: the plan's friction (its cones') and mass, no push."""
        return self.planned

    def UpdateActuation(self, context, discrete_state):
        schedule = self.plan_port.Eval(context).schedule
        offsets = context.get_discrete_state(self._offset_state).get_value().reshape(-1, 3)
        u, offsets = self.compute_actuation(
            schedule,
            context.get_time(),
            self.box_state_port.Eval(context),
            self.hand_state_port.Eval(context),
            offsets,
            self.estimates(context),
        )
        discrete_state.get_mutable_vector(0).set_value(u)
        discrete_state.get_mutable_vector(self._offset_state).set_value(offsets.ravel())
        return EventStatus.Succeeded()

    def _own_joints(self, J) -> np.ndarray:
        """(F, 3, n): each finger's block of the hand Jacobians J (F, 3, F n) (the columns of its own joints)."""
        F, n = self._num_fingers, self._joints_per_finger
        return J.reshape(F, 3, F, n)[np.arange(F), :, np.arange(F)]

    def fingertips(self, q) -> tuple[np.ndarray, np.ndarray, list]:
        """At joint angles q (F n, finger-major): the fingertip centres p_W (F, 3), their Jacobians J (F, 3, n) in
        each finger's own joints and the tip frames' poses in W, by the controller's own plant."""
        plant, context = self._plant, self._context
        plant.SetPositions(context, self._hand, q)
        world = plant.world_frame()
        poses = [frame.CalcPoseInWorld(context) for frame in self._tips]
        J = np.array(
            [
                plant.CalcJacobianTranslationalVelocity(context, JacobianWrtVariable.kV, f, np.zeros(3), world, world)
                for f in self._tips
            ]
        )[..., self._hand_v]
        return np.array([X.translation() for X in poses]), self._own_joints(J), poses

    def contact_jacobians(self, poses, r_TC_W) -> np.ndarray:
        """(F, 3, n), in each finger's own joints: the translational Jacobians of the points r_TC_W (F, 3) from each
        tip frame's origin (in W)."""
        plant, world = self._plant, self._plant.world_frame()
        J = np.array(
            [
                plant.CalcJacobianTranslationalVelocity(
                    self._context, JacobianWrtVariable.kV, f, X.rotation().inverse() @ r, world, world
                )
                for f, X, r in zip(self._tips, poses, r_TC_W)
            ]
        )
        return self._own_joints(J[..., self._hand_v])

    def tracking_torques(self, q, qdot, J_WF, a_target, error, rate_error) -> np.ndarray:
        """(F, n) N m that move each fingertip at a_target (F, 3) m/s^2 plus a critically damped correction of
        its position and rate errors (F, 3) at gains.grasp.swing_bandwidth, through its finger's own inertia: M J^+
        (a - Jdot qdot) + C qdot, J^+ damped least squares (near a straight finger the inverse is unbounded). The
        controller's context holds q; qdot is set here."""
        w = self.gains.grasp.swing_bandwidth
        plant, context = self._plant, self._context
        plant.SetVelocities(context, self._hand, qdot)
        F, n = self._num_fingers, self._joints_per_finger
        blocks = np.arange(F * n).reshape(F, n)
        M = plant.CalcMassMatrix(context)[np.ix_(self._hand_v, self._hand_v)]
        M = np.array([M[np.ix_(b, b)] for b in blocks])  # (F, n, n): the fingers are separate chains
        coriolis = plant.CalcBiasTerm(context)[self._hand_v].reshape(F, n)
        world = plant.world_frame()
        bias = np.array(
            [
                plant.CalcBiasTranslationalAcceleration(context, JacobianWrtVariable.kV, f, np.zeros(3), world, world)
                for f in self._tips
            ]
        )[..., 0]
        plant.SetVelocities(context, self._hand, np.zeros_like(qdot))
        a = a_target + w**2 * error + 2.0 * w * rate_error - bias
        JJt = J_WF @ np.swapaxes(J_WF, 1, 2) + SINGULAR_DAMPING**2 * np.eye(3)
        qdd = np.einsum("fcj,fc->fj", J_WF, np.linalg.solve(JJt, a[..., None])[..., 0])
        return np.einsum("fij,fj->fi", M, qdd) + coriolis

    def gravity_torques(self) -> np.ndarray:
        """(F, n) N m, the torques that hold the links up at the controller's context's joints."""
        tau = -self._plant.CalcGravityGeneralizedForces(self._context)[self._hand_v]
        return tau.reshape(self._num_fingers, -1)

    def desired_wrench(self, s: SpaceSchedule, n: int, box_state, estimates: Estimates | None = None) -> np.ndarray:
        """(6,) [N; N m] in W about the cube's centre: the plan's contact wrench at sample n and the pose feedback,
        for the `estimates`' mass (the plan's wrench and the cube's inertia scale with it: the same cube, denser),
        cancelling their disturbance; the push reflex raises the gains (kd with the square root of kp: the same
        damping ratio, a faster response), as the plane's (control.GraspController.desired_acceleration)."""
        g, reflex = self.gains.grasp, self.gains.push_reflex
        estimates = self.planned if estimates is None else estimates
        boost = 1.0 + estimates.reflex * (reflex.gain - 1.0)
        kp, kd = boost * g.object_kp, np.sqrt(boost) * g.object_kd
        scale = estimates.mass / self._mass
        quat, p, w, v = box_state[:4], box_state[4:7], box_state[7:10], box_state[10:13]
        R = quaternion_matrices(quat)
        e_R = quaternion_error_W(s.x[n, :4], quat / np.linalg.norm(quat))
        linear = estimates.mass * (kp * (s.x[n, 4:] - p) + kd * (s.v[n] - v))
        angular = R @ (self._I_B * scale) @ R.T @ (kp * e_R + kd * (s.w[n] - w))
        wrench = s.wrench[n] * scale + np.concatenate([linear, angular])
        wrench[:3] -= reflex.disturbance_feedforward * estimates.disturbance
        return wrench

    def compute_actuation(
        self, s: SpaceSchedule, t: float, box_state, hand_state, offsets, estimates: Estimates | None = None
    ) -> tuple:
        """(the actuation, the next swing offsets (F, 3) m in B) at time t following the schedule `s`, for the
        measured cube and hand states and the swing offsets: each finger's drift off its planned point along the
        face at the end of its lift-off hold, which its target carries on its swing (s.carry), so that it moves from
        where it lifted off rather than jumping back along the face (12 mm on seed-0 goal 1's first swing).
        `estimates`: what it assumes of the world (None: the plan's)."""
        g = self.gains.grasp
        estimates = self.planned if estimates is None else estimates
        n = s.index(t)
        nq = len(hand_state) // 2
        q, qdot = hand_state[:nq], hand_state[nq:]
        quat, p, w, v = box_state[:4], box_state[4:7], box_state[7:10], box_state[10:13]
        R = quaternion_matrices(quat)
        p_WF, J_WF, poses = self.fingertips(q)
        v_WF = np.einsum("fcj,fj->fc", J_WF, qdot.reshape(self._num_fingers, -1))
        r_BF = (s.p_BF[n] + s.carry[n][:, None] * offsets) @ R.T  # the targets, from the measured cube's centre
        p_target = p + r_BF
        v_target = v + np.cross(w, r_BF) + s.v_BF[n] @ R.T
        scale = s.force_scale[n]
        # The measured contacts: on the cube's face nearest each fingertip, tip_radius from its centre.
        n_W = box_face_normals(self._half, (p_WF - p) @ R) @ R.T
        # A holding fingertip is force-controlled: its spring fades with its force budget (as in the plane, where a
        # spring anchored to the cube fought the friction force as the sphere rolled); the moving one follows its path.
        # A sphere that held rolls off its planned point (12 mm over 3 s on seed-0 goal 1): while it unloads, its
        # spring lifts it off the face where it is, for pulled along the face it would drag the cube by friction.
        error = p_target - p_WF
        along_n = np.sum(error * n_W, axis=1, keepdims=True) * n_W
        lifting = s.lifting[n][:, None]
        offsets = np.where(lifting, offsets - (error - along_n) @ R, offsets)  # drift along the face, in B
        error = np.where(lifting, along_n, error)
        spring = g.tip_kp * (1.0 - scale)[:, None] * error + g.tip_kd * (v_target - v_WF)
        a_target = s.a_BF[n] @ R.T
        rest = self.gravity_torques() + np.einsum("fcj,fc->fj", J_WF, spring)
        rest += (1.0 - scale)[:, None] * self.tracking_torques(q, qdot, J_WF, a_target, error, v_target - v_WF)
        r_W = p_WF - self._tip_radius * n_W - p
        t1, t2 = tangent_basis(n_W)
        D = np.stack([-n_W, t1, t2], axis=-1)  # (F, 3, 3): each force component's direction
        J_WC = self.contact_jacobians(poses, -self._tip_radius * n_W)
        lambda_plan = np.einsum("fck,fc->fk", D, s.f_B[n] @ R.T) * scale[:, None]
        lam = self.grasp_forces(
            grasp_matrix_3d_W(r_W, n_W),
            self.desired_wrench(s, n, box_state, estimates),
            lambda_plan,
            scale * g.min_normal_force,
            scale * np.minimum(g.max_normal_force, np.maximum(s.unload_force[n], g.min_normal_force)),
            contact_torque_rows(J_WC, D, rest, self._tau_max),
            estimates,
            scale,
        )
        f_W = np.einsum("fck,fk->fc", D, lam)
        tau = rest + np.einsum("fcj,fc->fj", J_WC, f_W)
        return self._u_from_tau @ tau.ravel(), offsets

    def grasp_forces(self, G, wrench, lambda_plan, lo, hi, torque, estimates: Estimates, scale) -> np.ndarray:
        """lambda (F, 3), the fingertips' (normal, tangential 1, 2) forces that make `wrench` (SpaceGraspForceQp)
        within the normal-force bounds lo, hi (F,) N and the motors (`torque`), at the friction the QP was built
        with; the open loop's `estimates` and force budgets `scale` (F,) change nothing."""
        return self._qp.solve(G, wrench, lambda_plan, lo, hi, torque)


class SpaceClosedLoopGraspController(SpaceGraspController):
    """The grasp controller in space fed by the closed loop (trajectotree.execution.closed_loop with its
    SPACE_OBJECT layout), as the plane's ClosedLoopGraspController. Input ports as SpaceGraspController's, and
    `friction` (1: the friction estimate its cones follow, reflexes.ConeFriction's), `mass_estimate` (1, kg),
    `reflex` (1, 0..1) and `disturbance` (3, N in W). Output port `actuation` as SpaceGraspController's. Its cones
    are at the estimate times the open loop's safety fraction, its desired wrench is the estimated mass's and
    cancels the measured disturbance at once; the push reflex raises the object gains and the QP's target squeeze
    (gains.push_reflex.squeeze, a target, not a bound), puts its cones at push_reflex.friction_safety x the
    estimate and weights its torque residual by push_reflex.torque_weight. No landing reflex: the planar one runs
    a swing ahead along the plane's schedule, which space's five-stage swings (swing_timing) do not share."""

    def __init__(self, scene: SpaceScene, gains: ControllerGains, *, mu: float):
        super().__init__(scene, gains, mu=mu)
        self.estimate_ports = EstimatePorts.declare(self, disturbance_size=3)

    def estimates(self, context) -> Estimates:
        return self.estimate_ports.read(context)

    def grasp_forces(self, G, wrench, lambda_plan, lo, hi, torque, estimates: Estimates, scale) -> np.ndarray:
        """As SpaceGraspController's, at the estimated friction and, during the push reflex, with the squeeze as
        the QP's target push (its least the plan's) and the torque residual weighted."""
        pr = self.gains.push_reflex
        safety = self._friction_safety + estimates.reflex * max(pr.friction_safety - self._friction_safety, 0.0)
        self._qp.set_friction(safety * estimates.mu)
        target = np.array(lambda_plan, dtype=float)
        target[:, 0] = np.maximum(target[:, 0], estimates.reflex * np.minimum(scale * pr.squeeze, hi))
        weight = 1.0 + estimates.reflex * (pr.torque_weight - 1.0)
        return self._qp.solve(G, wrench, target, lo, hi, torque, torque_weight=weight)
