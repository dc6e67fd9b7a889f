"""How hard each plan's grasp can push back against a push, at the time the sweep's push
conditions push it (experiments.executions.middle_of_middle_segment): the largest force
along -FORCE_DIRECTION that the fingers holding at that time can apply to the box (an LP,
scipy's HiGHS) while they also hold its weight and apply no torque, each within the grasp
controller's force bound (controller.max_normal_force), the joint motors' tau_max (beside
gravity on the links) and friction cones at mu. It is the static limit of any controller
that keeps that grasp: a push above it moves the box for as long as it lasts. Printed per
plan at the planned pose and joint angles, for the cones of the open loop
(max(search, controller friction_safety) x scene.mu) and of the reflex
(controller.reflex_friction_safety x scene.mu), with the holding fingers.

    python scripts/push_capacity.py PLAN_DIR [PLAN_DIR ...] [--direction 1 0]
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import linprog

from trajectotree.execution.control import HandKinematics
from trajectotree.execution.reference import reference_from_plan
from trajectotree.execution.simulate import execution_schedule
from trajectotree.experiments.executions import middle_of_middle_segment
from trajectotree.geometry import rotation_2d
from trajectotree.io import load_plan
from trajectotree.scene.plant import build_scene
from trajectotree.scene.statics import cone_rows, perp, torque_rows


def push_capacity(G, torque, holding, mu: float, max_normal: float, weight: float, direction) -> float:
    """N, the most force along `direction` (unit, W) the fingers apply to the box with the grasp
    matrix G (3, 8), with G's other force component holding `weight` (N, along +y) and no torque;
    `torque` = (A, lower, upper) from control.torque_rows; `holding` (4,) which fingers may push."""
    A, lower, upper = torque
    along, across = np.asarray(direction, dtype=float), perp(np.asarray(direction, dtype=float))
    equality = np.vstack([across @ G[:2], G[2]])
    bounds = [b for h in holding for b in ((0.0, max_normal if h else 0.0), (None, None))]
    result = linprog(
        -(along @ G[:2]),
        A_ub=np.vstack([cone_rows(mu, len(holding)), A, -A]),
        b_ub=np.concatenate([np.zeros(2 * len(holding)), upper, -lower]),
        A_eq=equality,
        b_eq=[across @ np.array([0.0, weight]), 0.0],
        bounds=bounds,
    )
    return float(-result.fun) if result.success else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("plans", nargs="+", metavar="PLAN_DIR")
    parser.add_argument("--direction", nargs=2, type=float, default=(1.0, 0.0), metavar=("X", "Y"))
    args = parser.parse_args()
    push = np.array(args.direction) / np.linalg.norm(args.direction)
    for folder in args.plans:
        plan = load_plan(folder)
        config = plan.config
        scene, gains = build_scene(config.scene), config.controller
        reference = reference_from_plan(plan, scene)
        schedule = execution_schedule(reference, config, scene)
        t = middle_of_middle_segment(config, float(plan.trajectory.t[-1]))
        n = schedule.index(t)
        q = np.array([np.interp(t, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])])
        pose = schedule.X[n]
        n_W = schedule.n_B[n] @ rotation_2d(pose[2]).T
        t_W = perp(n_W)
        p_WF, J_WF, g_hand = HandKinematics(scene.fingers, config.scene.gravity)(q)
        r_W = p_WF - scene.tip_radius * n_W - pose[:2]
        G = np.empty((3, 8))
        G[:2, 0::2], G[:2, 1::2] = -n_W.T, t_W.T
        G[2, 0::2] = r_W[:, 0] * -n_W[:, 1] + r_W[:, 1] * n_W[:, 0]
        G[2, 1::2] = r_W[:, 0] * t_W[:, 1] - r_W[:, 1] * t_W[:, 0]
        tau_max = np.array([f.tau_max for f in scene.fingers])
        A, lower, upper, _ = torque_rows(J_WF, n_W, t_W, scene.tip_radius, g_hand, tau_max)
        holding = schedule.force_scale[n] >= 1.0
        weight = config.scene.box_mass * config.scene.gravity
        cones = {
            "open loop": max(config.search.friction_safety, gains.friction_safety) * config.scene.mu,
            "reflex": max(gains.reflex_friction_safety, gains.friction_safety) * config.scene.mu,
        }
        against = {
            name: push_capacity(G, (A, lower, upper), holding, mu, gains.max_normal_force, weight, -push)
            for name, mu in cones.items()
        }
        fingers = "".join(str(i) for i in np.flatnonzero(holding))
        text = ", ".join(f"{name} (mu {cones[name]:.2f}) {value:.1f} N" for name, value in against.items())
        print(f"{folder}: push at {t:.2f} s, fingers {fingers} hold; most force against the push: {text}")


if __name__ == "__main__":
    main()
