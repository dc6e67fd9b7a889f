"""Algorithm 1 in space on fingerpro4: how many of `--goals` orientations uniform over SO(3) (seed 0,
the cube's position unchanged) the contact-sequence search plans, and its time (mean, median, p90 over
all goals, planned or not), one process, this machine's CPU (tests/search/test_space_search.py
re-checks a plan's nodes: closure, holding within the motors, Drake's signed distances).

    python scripts/search_space.py                # 30 goals, seed 0
    python scripts/search_space.py --goals 5 --seed 1
    python scripts/search_space.py --axis-aligned   # the cube's 23 rotations but the identity
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from trajectotree.config import Config, mu_plan
from trajectotree.experiments.sweep import axis_aligned_goals
from trajectotree.geometry import quaternion_angle
from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.search.space_tree import find_space_contact_plan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--axis-aligned", action="store_true", help="the 23 axis-aligned orientations instead")
    args = parser.parse_args()
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    if args.axis_aligned:
        goals = axis_aligned_goals()
    else:
        goals = Rotation.random(args.goals, random_state=args.seed).as_quat(scalar_first=True)
    times, planned = [], 0
    for k, goal in enumerate(goals):
        t0 = time.perf_counter()
        plan = find_space_contact_plan(scene, goal, config.search, mu)
        times.append(time.perf_counter() - t0)
        planned += plan.success
        angle = np.degrees(quaternion_angle(START_POSE[:4], goal))
        switches = sum(n.switching_finger is not None for n in plan.nodes)
        print(
            f"goal {k:2d}: {angle:5.1f} deg, {'planned' if plan.success else 'NO PLAN'} in {times[-1]:.2f} s, "
            f"{len(plan.nodes)} nodes, {switches} switches, {plan.stats.expanded} expanded, "
            f"{plan.stats.ik_calls} IK, {plan.stats.lp_calls} LP" + ("" if plan.success else f": {plan.reason[:160]}")
        )
    t = np.array(times)
    print(
        f"planned {planned}/{len(goals)}; time mean {t.mean():.2f} s, median {np.median(t):.2f} s, "
        f"p90 {np.percentile(t, 90):.2f} s, max {t.max():.2f} s (mu_plan {mu:.3g})"
    )


if __name__ == "__main__":
    main()
