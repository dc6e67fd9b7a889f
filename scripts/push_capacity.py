"""How hard each plan's grasp can push back against a push, at the time the sweep's push
conditions push it (experiments.conditions.middle_of_middle_segment): the hardest push along
--direction that the fingers holding at that time resist while they also hold the box's weight,
each within the grasp controller's force bound (controller.grasp.max_normal_force), the joint motors'
tau_max (beside gravity on the links) and friction cones at mu: the LP the search orders its
children by (search.stance.PushCapacityLp), here at the executed contacts and joint angles. It is
the static limit of any controller that keeps that grasp: a push above it moves the box for as
long as it lasts. Printed per plan for the cones of the open loop (max(search, controller
friction_safety) x scene.mu) and of the reflex (controller.push_reflex.friction_safety x scene.mu).

    python scripts/push_capacity.py PLAN_DIR [PLAN_DIR ...] [--direction 1 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from trajectotree.execution.fingers import HandKinematics
from trajectotree.execution.in_effect import execution_schedule
from trajectotree.execution.reference import reference_from_plan
from trajectotree.experiments.conditions import middle_of_middle_segment
from trajectotree.geometry import rotation_2d
from trajectotree.io import load_plan
from trajectotree.scene.plant import build_scene
from trajectotree.scene.statics import grasp_matrix_W, perp, torque_rows
from trajectotree.search.stance import PushCapacityLp


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
        holding = np.flatnonzero(schedule.force_scale[n] >= 1.0)
        G = grasp_matrix_W(r_W[holding], n_W[holding])
        tau_max = np.array([f.tau_max for f in scene.fingers])[holding]
        A, lower, upper, _ = torque_rows(
            J_WF[holding], n_W[holding], t_W[holding], scene.tip_radius, g_hand[holding], tau_max
        )
        w_hold = np.array([0.0, config.scene.box_mass * config.scene.gravity, 0.0])
        cones = {
            "open loop": max(config.search.friction_safety, gains.grasp.friction_safety) * config.scene.mu,
            "reflex": max(gains.push_reflex.friction_safety, gains.grasp.friction_safety) * config.scene.mu,
        }
        against = {
            name: PushCapacityLp(len(holding), mu, gains.grasp.max_normal_force).solve(
                G, (A, lower, upper), w_hold, push
            )
            for name, mu in cones.items()
        }
        fingers = "".join(str(i) for i in holding)
        text = ", ".join(f"{name} (mu {cones[name]:.2f}) {value:.1f} N" for name, value in against.items())
        print(f"{folder}: push at {t:.2f} s, fingers {fingers} hold; most force against the push: {text}")


if __name__ == "__main__":
    main()
