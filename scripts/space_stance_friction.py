"""The least friction each stance of a plan in space needs to make its own contact wrench within the motors (issue 37,
friction 0.4; docs/measurements.md "Executing plans in space, closed loop"): `python scripts/space_stance_friction.py
PLAN_DIR...` prints per plan the most that its four-finger and its three-finger stances need, every 0.02 s of the
plan where no force budget is ramping, at the planned cube pose and joints (linear between knots), by the grasp
controller's kinematics: the contacts on the faces nearest the fingertips, the normal force in the QP's bounds
(controller.grasp min_normal_force, max_normal_force), the pyramids of space_control.CONE_FACETS facets and the
motors' tau_max with the links' weight on them (contact_torque_rows); bisection on an LP's feasibility (HiGHS)."""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

from trajectotree.config import config_from_dict
from trajectotree.execution.executor import control_friction
from trajectotree.execution.space_control import CONE_FACETS, SpaceGraspController, SpaceReference
from trajectotree.execution.space_plan import read_space_plan
from trajectotree.execution.space_run import space_plan_in_effect
from trajectotree.geometry import box_face_normals, quaternion_matrices
from trajectotree.scene.spatial import build_space_scene
from trajectotree.scene.statics import cone_rows_3d, contact_torque_rows, grasp_matrix_3d_W, tangent_basis

STEP = 0.02  # s between the stances checked
MOST = 1.5  # the friction bisected up to (inf beyond)


def holds(G, wrench, lo, hi, torque, mu: float) -> bool:
    """Some forces (lambda_n, lambda_1, lambda_2) per finger make `wrench` with G, lambda_n in [lo, hi], inside the
    pyramids at mu and within the motors' rows `torque` (A, lower, upper)."""
    F = G.shape[1] // 3
    A, lower, upper = torque
    cones = cone_rows_3d(mu, F, CONE_FACETS)
    bounds = [b for i in range(F) for b in ((lo[i], hi[i]), (None, None), (None, None))]
    rows, limits = np.vstack([cones, A, -A]), np.concatenate([np.zeros(len(cones)), upper, -lower])
    return linprog(np.zeros(3 * F), A_ub=rows, b_ub=limits, A_eq=G, b_eq=wrench, bounds=bounds).status == 0


def least_friction(*stance) -> float:
    if not holds(*stance, MOST):
        return np.inf
    low, high = 0.0, MOST
    for _ in range(14):  # to 1e-4
        mid = 0.5 * (low + high)
        low, high = (low, mid) if holds(*stance, mid) else (mid, high)
    return high


def stance_needs(plan_dir: Path) -> np.ndarray:
    """(T, 2): per checked time the number of loaded fingers and the least friction their stance needs."""
    data, arrays = read_space_plan(plan_dir)
    config = config_from_dict(data["config"])
    cube = data["object"]
    scene = build_space_scene(
        config.scene.hand, mu=config.scene.mu, gravity=config.scene.gravity, size=cube["size"], mass=cube["mass"]
    )
    reference = SpaceReference.from_arrays(arrays)
    s = space_plan_in_effect(reference, config, scene).schedule
    controller = SpaceGraspController(scene, config.controller, mu=control_friction(config))
    g = config.controller.grasp
    times = np.arange(0.0, reference.duration, STEP)
    qs = np.column_stack([np.interp(times, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])])
    rows = []
    for t, q in zip(times, qs):
        n = s.index(t)
        scale = s.force_scale[n]
        if np.any((scale > 0.0) & (scale < 1.0)):
            continue  # a budget ramping: the plan hands a load over
        R, p = quaternion_matrices(s.x[n, :4]), s.x[n, 4:]
        p_WF, _, poses = controller.fingertips(q)
        n_W = box_face_normals(scene.object.half, (p_WF - p) @ R) @ R.T
        D = np.stack([-n_W, *tangent_basis(n_W)], axis=-1)
        J_WC = controller.contact_jacobians(poses, -scene.tip_radius * n_W)
        torque = contact_torque_rows(J_WC, D, controller.gravity_torques(), scene.tau_max)
        G = grasp_matrix_3d_W(p_WF - scene.tip_radius * n_W - p, n_W)
        need = least_friction(G, s.wrench[n], scale * g.min_normal_force, scale * g.max_normal_force, torque)
        rows.append((int(np.sum(scale > 0.0)), need))
    return np.array(rows)


def main(argv: list[str]) -> int:
    for plan_dir in map(Path, argv):
        needs = stance_needs(plan_dir)
        most = {k: np.max(needs[needs[:, 0] == k, 1], initial=-np.inf) for k in (4, 3)}  # -inf: no such stance
        print(
            f"{plan_dir.name}: four fingers need at most {most[4]:.3f}, three {most[3]:.3f}; "
            f"time above 0.32: {np.mean(needs[:, 1] > 0.32):.2f}, above 0.40: {np.mean(needs[:, 1] > 0.40):.2f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
