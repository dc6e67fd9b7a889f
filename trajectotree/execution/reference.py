"""What the execution tracks: fingertip and object references over time.

A `Reference` is built from a plan's arrays (the `plan.npz` names that
`trajectotree.io.save_plan` writes) or, for controller tests, from a static grasp (`static_hold_reference`),
so the simulation depends on the plan's data, not on the planner's code.

Fingertip positions are the centres of the fingertip spheres (the hand description's
tip frames); forces are those of each finger ON the box, in W.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from pydrake.solvers import MathematicalProgram, Solve

from trajectotree.geometry import ConvexPolygon, box_to_world, poses_world_to_box, rotation_2d, rotations_2d
from trajectotree.results import TRAJECTORY_ARRAYS as PLAN_ARRAYS
from trajectotree.scene.plant import JOINTS_PER_FINGER, Scene


@dataclass(frozen=True)
class Reference:
    t: np.ndarray  # (K,) s, knot times, increasing, t[0] = 0
    x: np.ndarray  # (K, 3) planned object pose (x m, y m, theta rad)
    q: np.ndarray  # (K, 2F) rad, planned joint angles (finger-major) of the F fingers
    p_WF: np.ndarray  # (K, F, 2) m, fingertip sphere centres in W
    v_WF: np.ndarray  # (K, F, 2) m/s, fingertip velocities in W
    f_W: np.ndarray  # (K, F, 2) N, force of each finger on the box, in W
    xdot: np.ndarray | None = None  # (K, 3) planned object velocity (m/s, m/s, rad/s); None: finite differences of x
    p_WC: np.ndarray | None = None  # (K, F, 2) m, where each finger's force acts; None: nearest box point to p_WF

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def object_pose_at(self, times) -> np.ndarray:
        """(T, 3) planned object pose, linearly interpolated, held after the end."""
        return self._at(self.x, times)

    def forces_at(self, times) -> np.ndarray:
        """(T, F, 2) planned finger forces on the box, linearly interpolated, held after the end."""
        return self._at(self.f_W, times)

    def _at(self, values: np.ndarray, times) -> np.ndarray:
        """values (K, ...) at the knots, linearly interpolated to times (T,): (T, ...)."""
        times = np.asarray(times, dtype=float)
        flat = values.reshape(len(self.t), -1)
        columns = [np.interp(times, self.t, flat[:, j]) for j in range(flat.shape[1])]
        return np.stack(columns, axis=1).reshape((len(times),) + values.shape[1:])


def check_plan_arrays(arrays, num_fingers: int | None = None) -> dict[str, np.ndarray]:
    """The plan.npz arrays as float arrays with consistent shapes for a hand of `num_fingers`
    fingers (None: as many as lambda_n has columns); raises ValueError naming the first missing
    or malformed array (callers map it to their input error)."""
    missing = [name for name in PLAN_ARRAYS if name not in arrays]
    if missing:
        raise ValueError(f"plan arrays lack {missing}")
    out = {name: np.asarray(arrays[name], dtype=float) for name in PLAN_ARRAYS}
    K = out["t"].shape[0] if out["t"].ndim == 1 else -1
    if num_fingers is None:
        num_fingers = out["lambda_n"].shape[1] if out["lambda_n"].ndim == 2 else -1
    F, J = num_fingers, JOINTS_PER_FINGER * num_fingers
    shapes = {
        "t": (K,),
        "x": (K, 3),
        "xdot": (K, 3),
        "q": (K, J),
        "qdot": (K, J),
        "tau": (K, J),
        "lambda_n": (K, F),
        "lambda_t": (K, F),
        "f_W": (K, F, 2),
        "p_W_tip": (K, F, 2),
        "p_W_C": (K, F, 2),
    }
    for name, shape in shapes.items():
        if K < 2 or F < 1 or out[name].shape != shape:
            raise ValueError(f"plan array {name!r} has shape {out[name].shape}, expected {shape} with K >= 2 knots")
        if not np.all(np.isfinite(out[name])):
            raise ValueError(f"plan array {name!r} holds non-finite values")
    if np.any(np.diff(out["t"]) <= 0):
        raise ValueError("plan array 't' is not strictly increasing")
    return out


def reference_from_arrays(arrays, scene: Scene) -> Reference:
    """The reference of a plan from its plan.npz arrays. Fingertip velocities are
    J_WF(q) qdot, consistent with the planned joint motion."""
    a = check_plan_arrays(arrays, scene.num_fingers)
    J = np.array([scene.fingertip_jacobians(q) for q in a["q"]])  # (K, F, 2, 2F)
    v_WF = np.einsum("kfij,kj->kfi", J, a["qdot"])
    return Reference(
        t=a["t"] - a["t"][0],
        x=a["x"],
        q=a["q"],
        p_WF=a["p_W_tip"],
        v_WF=v_WF,
        f_W=a["f_W"],
        xdot=a["xdot"],
        p_WC=a.get("p_W_C"),
    )


def reference_from_plan(plan, scene: Scene) -> Reference:
    """From a PlanResult (its `.trajectory` holds the plan.npz arrays, as attributes
    or as a mapping), or from a Reference, which passes through."""
    if isinstance(plan, Reference):
        return plan
    trajectory = getattr(plan, "trajectory", plan)
    if trajectory is None:
        raise ValueError("the plan has no trajectory (did planning fail?)")
    if hasattr(trajectory, "keys"):
        arrays = {name: trajectory[name] for name in PLAN_ARRAYS if name in trajectory}
    else:
        arrays = {name: getattr(trajectory, name) for name in PLAN_ARRAYS if hasattr(trajectory, name)}
    return reference_from_arrays(arrays, scene)


def static_grasp_forces(
    p_BC,
    n_B,
    pose,
    *,
    mass: float,
    gravity: float,
    mu: float,
    min_normal_force: float,
    friction_margin: float = 0.8,
    lifted: int | None = None,
) -> np.ndarray | None:
    """Finger forces on the box (F, 2) in W, one row per contact of p_BC (F, 2) that hold it still against gravity:
    the least-squares forces with every normal force >= min_normal_force (the
    squeeze) inside a friction cone shrunk by friction_margin; finger `lifted`
    (if any) pushes with none. None if infeasible."""
    R_WB = rotation_2d(pose[2])
    n_W = (R_WB @ np.asarray(n_B, dtype=float).T).T
    t_W = np.stack([-n_W[:, 1], n_W[:, 0]], axis=1)
    r_W = (R_WB @ np.asarray(p_BC, dtype=float).T).T  # contact points relative to the box origin
    prog = MathematicalProgram()
    F = len(n_W)
    lam_n = prog.NewContinuousVariables(F, "lambda_n")
    lam_t = prog.NewContinuousVariables(F, "lambda_t")
    # force of finger i on the box: pushes along the inward normal, slides along the tangent
    fx = [-lam_n[i] * n_W[i, 0] + lam_t[i] * t_W[i, 0] for i in range(F)]
    fy = [-lam_n[i] * n_W[i, 1] + lam_t[i] * t_W[i, 1] for i in range(F)]
    prog.AddLinearEqualityConstraint(sum(fx) == 0.0)
    prog.AddLinearEqualityConstraint(sum(fy) - mass * gravity == 0.0)
    prog.AddLinearEqualityConstraint(sum(r_W[i, 0] * fy[i] - r_W[i, 1] * fx[i] for i in range(F)) == 0.0)
    mu_eff = friction_margin * mu
    for i in range(F):
        if i == lifted:
            prog.AddLinearEqualityConstraint(lam_n[i] == 0.0)
        prog.AddLinearConstraint(lam_n[i] >= (0.0 if i == lifted else min_normal_force))
        prog.AddLinearConstraint(lam_t[i] <= mu_eff * lam_n[i])
        prog.AddLinearConstraint(-lam_t[i] <= mu_eff * lam_n[i])
    prog.AddQuadraticCost(2 * np.eye(2 * F), np.zeros(2 * F), np.r_[lam_n, lam_t], is_convex=True)
    result = Solve(prog)
    if not result.is_success():
        return None
    ln, lt = result.GetSolution(lam_n), result.GetSolution(lam_t)
    return -ln[:, None] * n_W + lt[:, None] * t_W


def static_hold_reference(
    scene: Scene,
    arclengths,
    *,
    min_normal_force: float,
    duration: float,
    pose=None,
    lifted: int | None = None,
    lift: float = 0.01,
) -> Reference | None:
    """A constant reference that holds the box at `pose` (default: the scene's
    initial pose) with contacts at `arclengths`: fingertip centres one tip radius
    outside the faces, joint angles by IK, forces from `static_grasp_forces`.
    Finger `lifted` (if any) stays `lift` m off its face and pushes with none.
    None if unreachable or not holdable."""
    c = scene.config
    pose = np.asarray(c.initial_pose if pose is None else pose, dtype=float)
    boundary = c.shape
    points = [boundary.point(s) for s in arclengths]
    p_BC = np.array([p for p, _ in points])
    n_B = np.array([n for _, n in points])
    gaps = [lift if i == lifted else 0.0 for i in range(scene.num_fingers)]
    p_WF = np.array([box_to_world(pose, p + (scene.tip_radius + g) * n) for p, n, g in zip(p_BC, n_B, gaps)])
    q = np.zeros(scene.num_hand_joints)
    for i, finger in enumerate(scene.fingers):
        q_i = finger.ik_one(p_WF[i], elbow=1)  # the model's elbow side
        if q_i is None:
            return None
        q[2 * i : 2 * i + 2] = q_i
    f_W = static_grasp_forces(
        p_BC, n_B, pose, mass=c.box_mass, gravity=c.gravity, mu=c.mu, min_normal_force=min_normal_force, lifted=lifted
    )
    if f_W is None:
        return None
    K = 2
    return Reference(
        t=np.array([0.0, duration]),
        x=np.tile(pose, (K, 1)),
        q=np.tile(q, (K, 1)),
        p_WF=np.tile(p_WF, (K, 1, 1)),
        v_WF=np.zeros((K, scene.num_fingers, 2)),
        f_W=np.tile(f_W, (K, 1, 1)),
    )


@dataclass(frozen=True)
class GraspSchedule:
    """What the GraspController tracks, sampled at its control times n * period
    (n = 0 .. N-1) and held after the plan ends. Built from the plan's arrays alone:
    a finger is in contact where its planned fingertip is within `contact_distance`
    of the planned box, so no planner internals are needed."""

    period: float  # s, control period
    X: np.ndarray  # (N, 3) planned object pose: cubic Hermite through the plan's x, xdot
    V: np.ndarray  # (N, 3) its velocity (m/s, m/s, rad/s)
    A: np.ndarray  # (N, 3) its acceleration
    p_BF: np.ndarray  # (N, F, 2) m, fingertip targets in B (a swinging finger lifted to >= swing_lift)
    v_BF: np.ndarray  # (N, F, 2) m/s, their rates in B
    p_BC: np.ndarray  # (N, F, 2) m, contact points in B
    n_B: np.ndarray  # (N, F, 2) outward unit normals of the faces at p_BC
    lambda_plan: np.ndarray  # (N, F, 2) N, planned (normal, tangential) force along (-n_B, t_B), times force_scale
    force_scale: np.ndarray  # (N, F) 1 holding, 0 swinging, ramped over ramp_time around lift-off and landing

    def index(self, t: float) -> int:
        return min(int(round(t / self.period)), len(self.X) - 1)

    @cached_property
    def landing(self) -> np.ndarray:
        """(N, F) int, next_landing of force_scale: computed once per schedule, for every system that follows it."""
        return next_landing(self.force_scale)


def next_landing(force_scale: np.ndarray) -> np.ndarray:
    """(N, F) int: for each sample n and finger, the first sample >= n where the finger's force
    budget is full again (its next planned landing, or n itself while it holds), -1 if none."""
    N, F = force_scale.shape
    out = np.full((N, F), -1, dtype=int)
    nxt = np.full(F, -1, dtype=int)
    for n in range(N - 1, -1, -1):
        nxt = np.where(force_scale[n] >= 1.0, n, nxt)
        out[n] = nxt
    return out


def hermite(t_knots, values, rates, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubic Hermite through (values, rates) (K, n) at t_knots: value, rate and second
    derivative at `times` (T,), held (zero rates) after the last knot."""
    times = np.asarray(times, dtype=float)
    k = np.clip(np.searchsorted(t_knots, times, side="right") - 1, 0, len(t_knots) - 2)
    h = (t_knots[k + 1] - t_knots[k])[:, None]
    s = np.clip((times[:, None] - t_knots[k][:, None]) / h, 0.0, 1.0)
    p0, p1, m0, m1 = values[k], values[k + 1], h * rates[k], h * rates[k + 1]
    value = (
        (2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * m0 + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * m1
    )
    rate = (
        (6 * s**2 - 6 * s) * p0 + (3 * s**2 - 4 * s + 1) * m0 + (-6 * s**2 + 6 * s) * p1 + (3 * s**2 - 2 * s) * m1
    ) / h
    accel = ((12 * s - 6) * p0 + (6 * s - 4) * m0 + (6 - 12 * s) * p1 + (6 * s - 2) * m1) / h**2
    after = times > t_knots[-1]
    value[after], rate[after], accel[after] = values[-1], 0.0, 0.0
    return value, rate, accel


def swing_intervals(t_knots, in_contact) -> list[tuple[float, float]]:
    """(lift-off, landing) times of each run of knots out of contact: the last contact
    knot before and the first after (-inf / inf where the run starts or ends the plan)."""
    intervals, K = [], len(t_knots)
    k = 0
    while k < K:
        if in_contact[k]:
            k += 1
            continue
        start = k
        while k < K and not in_contact[k]:
            k += 1
        intervals.append((t_knots[start - 1] if start > 0 else -np.inf, t_knots[k] if k < K else np.inf))
    return intervals


def swing_profile(times, intervals, ramp_time: float) -> tuple[np.ndarray, np.ndarray]:
    """(force scale (T,), swing phase (T,)) of one finger. The scale is 1 outside the swing
    intervals and 0 in their cores, falling linearly over ramp_time after lift-off and
    rising over ramp_time before landing (halfway where an interval is shorter than
    2 ramp_time): the plan hands the load over between the knots next to a switch, and
    ramping before lift-off instead left two fingers holding where the plan has three
    (a box dropped on such a handover). The phase runs 0 -> 1 across an interval (0.5 for
    an open-ended one) and is nan outside."""
    distance = np.full(len(times), np.inf)  # to the nearest zero-force core
    phase = np.full(len(times), np.nan)
    for lo, hi in intervals:
        core_lo, core_hi = lo + ramp_time, hi - ramp_time
        if core_lo > core_hi:
            core_lo = core_hi = 0.5 * (lo + hi)
        distance = np.minimum(distance, np.maximum(core_lo - times, 0.0) + np.maximum(times - core_hi, 0.0))
        inside = (times > lo) & (times < hi)
        phase[inside] = (times[inside] - lo) / (hi - lo) if np.isfinite(hi - lo) else 0.5
    scale = np.clip(distance / ramp_time, 0.0, 1.0) if ramp_time > 0 else (distance > 0).astype(float)
    return scale, phase


def grasp_schedule(
    reference: Reference,
    *,
    shape: ConvexPolygon,
    tip_radius: float,
    period: float,
    duration: float,
    ramp_time: float,
    swing_lift: float,
    contact_distance: float,
) -> GraspSchedule:
    """The GraspSchedule of `reference` on the control grid 0, period, ... <= duration."""
    t, x = reference.t, reference.x
    times = np.arange(int(np.floor(duration / period + 1e-9)) + 1) * period
    xdot = reference.xdot if reference.xdot is not None else np.gradient(x, t, axis=0)
    X, V, A = hermite(t, x, xdot, times)
    p_BF_knots = poses_world_to_box(x, reference.p_WF)
    gap_knots = shape.signed_distances(p_BF_knots) - tip_radius  # (K, F)
    if reference.p_WC is not None:
        p_BC_knots = poses_world_to_box(x, reference.p_WC)
    else:  # the nearest box point: the fingertip centre minus its radius along the outward direction
        p_BC_knots = shape.nearest_points(p_BF_knots)
    f_B_knots = np.einsum("kba,kpb->kpa", rotations_2d(x[:, 2]), reference.f_W)  # R_BW f_W

    def at(values):
        return reference._at(values, times)

    p_BF, p_BC, f_B, gap = at(p_BF_knots), at(p_BC_knots), at(f_B_knots), at(gap_knots)
    n_B = shape.face_normals(p_BC)
    t_B = np.stack([-n_B[..., 1], n_B[..., 0]], axis=-1)
    F = reference.p_WF.shape[1]
    scale, phase = np.ones((len(times), F)), np.full((len(times), F), np.nan)
    for i in range(F):
        intervals = swing_intervals(t, gap_knots[:, i] <= contact_distance)
        scale[:, i], phase[:, i] = swing_profile(times, intervals, ramp_time)
    # Lift a swinging fingertip to at least swing_lift sin(pi phase), away from the nearest box point.
    away = p_BF - shape.nearest_points(p_BF)
    away /= np.maximum(np.linalg.norm(away, axis=-1, keepdims=True), 1e-9)
    extra = np.nan_to_num(np.maximum(swing_lift * np.sin(np.pi * phase) - gap, 0.0))
    p_BF = p_BF + extra[..., None] * away
    v_BF = np.gradient(p_BF, times, axis=0) if len(times) > 1 else np.zeros_like(p_BF)
    lambda_plan = np.stack([-np.sum(f_B * n_B, axis=-1), np.sum(f_B * t_B, axis=-1)], axis=-1) * scale[..., None]
    return GraspSchedule(
        period=period,
        X=X,
        V=V,
        A=A,
        p_BF=p_BF,
        v_BF=v_BF,
        p_BC=p_BC,
        n_B=n_B,
        lambda_plan=lambda_plan,
        force_scale=scale,
    )
