"""What the execution tracks: fingertip and object references over time.

A `Reference` is built from a plan's arrays (the `plan.npz` names, see DESIGN.md
sec. 5) or, for controller tests, from a static grasp (`static_hold_reference`),
so the simulation depends on the plan's data, not on the planner's code.

Fingertip positions are the centres of the fingertip spheres (the plant's
`finger{i}_tip` frames); forces are those of each finger ON the box, in W.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.solvers import MathematicalProgram, Solve

from trajectotree.geometry import BoxBoundary, box_to_world, rotation_2d
from trajectotree.scene import NUM_FINGERS, NUM_HAND_JOINTS, FingerGeometry, Scene

PLAN_ARRAYS = ("t", "x", "xdot", "q", "qdot", "tau", "lambda_n", "lambda_t", "f_W", "p_W_tip", "p_W_C")


@dataclass(frozen=True)
class Reference:
    t: np.ndarray      # (K,) s, knot times, increasing, t[0] = 0
    x: np.ndarray      # (K, 3) planned object pose (x m, y m, theta rad)
    q: np.ndarray      # (K, 8) rad, planned joint angles (finger-major)
    p_WF: np.ndarray   # (K, 4, 2) m, fingertip sphere centres in W
    v_WF: np.ndarray   # (K, 4, 2) m/s, fingertip velocities in W
    f_W: np.ndarray    # (K, 4, 2) N, force of each finger on the box, in W

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def object_pose_at(self, times) -> np.ndarray:
        """(T, 3) planned object pose, linearly interpolated, held after the end."""
        return self._at(self.x, times)

    def forces_at(self, times) -> np.ndarray:
        """(T, 4, 2) planned finger forces on the box, linearly interpolated, held after the end."""
        return self._at(self.f_W, times)

    def _at(self, values: np.ndarray, times) -> np.ndarray:
        """values (K, ...) at the knots, linearly interpolated to times (T,): (T, ...)."""
        times = np.asarray(times, dtype=float)
        flat = values.reshape(len(self.t), -1)
        columns = [np.interp(times, self.t, flat[:, j]) for j in range(flat.shape[1])]
        return np.stack(columns, axis=1).reshape((len(times),) + values.shape[1:])


def check_plan_arrays(arrays) -> dict[str, np.ndarray]:
    """The plan.npz arrays as float arrays with consistent shapes; raises ValueError
    naming the first missing or malformed array (callers map it to their input error)."""
    missing = [name for name in PLAN_ARRAYS if name not in arrays]
    if missing:
        raise ValueError(f"plan arrays lack {missing}")
    out = {name: np.asarray(arrays[name], dtype=float) for name in PLAN_ARRAYS}
    K = out["t"].shape[0] if out["t"].ndim == 1 else -1
    shapes = {"t": (K,), "x": (K, 3), "xdot": (K, 3), "q": (K, 8), "qdot": (K, 8), "tau": (K, 8),
              "lambda_n": (K, 4), "lambda_t": (K, 4), "f_W": (K, 4, 2), "p_W_tip": (K, 4, 2), "p_W_C": (K, 4, 2)}
    for name, shape in shapes.items():
        if K < 2 or out[name].shape != shape:
            raise ValueError(f"plan array {name!r} has shape {out[name].shape}, expected {shape} with K >= 2 knots")
        if not np.all(np.isfinite(out[name])):
            raise ValueError(f"plan array {name!r} holds non-finite values")
    if np.any(np.diff(out["t"]) <= 0):
        raise ValueError("plan array 't' is not strictly increasing")
    return out


def reference_from_arrays(arrays, scene: Scene) -> Reference:
    """The reference of a plan from its plan.npz arrays. Fingertip velocities are
    J_WF(q) qdot, consistent with the planned joint motion."""
    a = check_plan_arrays(arrays)
    J = np.array([scene.fingertip_jacobians(q) for q in a["q"]])       # (K, 4, 2, 8)
    v_WF = np.einsum("kfij,kj->kfi", J, a["qdot"])
    return Reference(t=a["t"] - a["t"][0], x=a["x"], q=a["q"], p_WF=a["p_W_tip"], v_WF=v_WF, f_W=a["f_W"])


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


def finger_ik(finger: FingerGeometry, p_WF) -> np.ndarray | None:
    """Closed-form 2-link IK with the second joint positive (the model's elbow
    side); None when p_WF is out of reach or outside the joint limits."""
    d = np.asarray(p_WF, dtype=float) - finger.p_W_base
    c2 = (d @ d - finger.l1 ** 2 - finger.l2 ** 2) / (2 * finger.l1 * finger.l2)
    if abs(c2) > 1.0:
        return None
    q2 = np.arccos(c2)
    q1 = np.arctan2(d[1], d[0]) - finger.psi - np.arctan2(finger.l2 * np.sin(q2), finger.l1 + finger.l2 * np.cos(q2))
    q = np.array([(q1 + np.pi) % (2 * np.pi) - np.pi, q2])
    if np.any(q < finger.q_lower) or np.any(q > finger.q_upper):
        return None
    return q


def static_grasp_forces(p_BC, n_B, pose, *, mass: float, gravity: float, mu: float,
                        min_normal_force: float, friction_margin: float = 0.8) -> np.ndarray | None:
    """Finger forces on the box (4, 2) in W that hold it still against gravity:
    the least-squares forces with every normal force >= min_normal_force (the
    squeeze) inside a friction cone shrunk by friction_margin. None if infeasible."""
    R_WB = rotation_2d(pose[2])
    n_W = (R_WB @ np.asarray(n_B, dtype=float).T).T
    t_W = np.stack([-n_W[:, 1], n_W[:, 0]], axis=1)
    r_W = (R_WB @ np.asarray(p_BC, dtype=float).T).T          # contact points relative to the box origin
    prog = MathematicalProgram()
    lam_n = prog.NewContinuousVariables(NUM_FINGERS, "lambda_n")
    lam_t = prog.NewContinuousVariables(NUM_FINGERS, "lambda_t")
    # force of finger i on the box: pushes along the inward normal, slides along the tangent
    fx = [-lam_n[i] * n_W[i, 0] + lam_t[i] * t_W[i, 0] for i in range(NUM_FINGERS)]
    fy = [-lam_n[i] * n_W[i, 1] + lam_t[i] * t_W[i, 1] for i in range(NUM_FINGERS)]
    prog.AddLinearEqualityConstraint(sum(fx) == 0.0)
    prog.AddLinearEqualityConstraint(sum(fy) - mass * gravity == 0.0)
    prog.AddLinearEqualityConstraint(sum(r_W[i, 0] * fy[i] - r_W[i, 1] * fx[i] for i in range(NUM_FINGERS)) == 0.0)
    mu_eff = friction_margin * mu
    for i in range(NUM_FINGERS):
        prog.AddLinearConstraint(lam_n[i] >= min_normal_force)
        prog.AddLinearConstraint(lam_t[i] <= mu_eff * lam_n[i])
        prog.AddLinearConstraint(-lam_t[i] <= mu_eff * lam_n[i])
    prog.AddQuadraticCost(2 * np.eye(2 * NUM_FINGERS), np.zeros(2 * NUM_FINGERS), np.r_[lam_n, lam_t], is_convex=True)
    result = Solve(prog)
    if not result.is_success():
        return None
    ln, lt = result.GetSolution(lam_n), result.GetSolution(lam_t)
    return -ln[:, None] * n_W + lt[:, None] * t_W


def static_hold_reference(scene: Scene, arclengths, *, min_normal_force: float, duration: float,
                          pose=None) -> Reference | None:
    """A constant reference that holds the box at `pose` (default: the scene's
    initial pose) with contacts at `arclengths`: fingertip centres one tip radius
    outside the faces, joint angles by IK, forces from `static_grasp_forces`.
    None if unreachable or not holdable."""
    c = scene.config
    pose = np.asarray(c.initial_pose if pose is None else pose, dtype=float)
    boundary = BoxBoundary(c.box_width, c.box_height)
    points = [boundary.point(s) for s in arclengths]
    p_BC = np.array([p for p, _ in points])
    n_B = np.array([n for _, n in points])
    p_WF = np.array([box_to_world(pose, p + scene.tip_radius * n) for p, n in zip(p_BC, n_B)])
    q = np.zeros(NUM_HAND_JOINTS)
    for i, finger in enumerate(scene.fingers):
        q_i = finger_ik(finger, p_WF[i])
        if q_i is None:
            return None
        q[2 * i:2 * i + 2] = q_i
    f_W = static_grasp_forces(p_BC, n_B, pose, mass=c.box_mass, gravity=c.gravity, mu=c.mu,
                              min_normal_force=min_normal_force)
    if f_W is None:
        return None
    K = 2
    return Reference(t=np.array([0.0, duration]), x=np.tile(pose, (K, 1)), q=np.tile(q, (K, 1)),
                     p_WF=np.tile(p_WF, (K, 1, 1)), v_WF=np.zeros((K, NUM_FINGERS, 2)), f_W=np.tile(f_W, (K, 1, 1)))
