"""Planning in space on fingerpro4 (search + the keyframes programs in space): of `--goals` orientations uniform
over SO(3) (seed 0, the cube's position unchanged), how many are planned, pass the 3D physics check and end
within 2 deg of their goal, and the planning time (mean, median, p90 over all goals), one process, the
segments one after another, this machine's CPU.

    python scripts/bench_space.py                # 30 goals, seed 0
    python scripts/bench_space.py --goals 5 --first 10
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from trajectotree.config import Config
from trajectotree.geometry import quaternion_angle
from trajectotree.planning.spatial import plan_space
from trajectotree.scene.spatial import START_POSE, build_space_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--first", type=int, default=0, help="start at this goal of the seed's list")
    args = parser.parse_args()
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    goals = Rotation.random(args.goals, random_state=args.seed).as_quat(scalar_first=True)
    times, searched, checked, planned = [], 0, 0, 0
    for k in range(args.first, args.goals):
        goal = goals[k]
        t0 = time.perf_counter()
        result = plan_space(scene, goal, config)
        times.append(time.perf_counter() - t0)
        searched += result.contact_plan.success
        check = result.physics_check
        checked += check is not None and check.passed
        planned += result.success
        angle = np.degrees(quaternion_angle(START_POSE[:4], goal))
        error = np.degrees(result.final_error_rad)
        print(
            f"goal {k:2d}: {angle:5.1f} deg, {'planned' if result.success else 'NOT PLANNED'} in {times[-1]:.1f} s "
            f"(search {result.search_time_s:.1f} s, {len(result.segments)} segments {result.solve_time_s:.1f} s), "
            f"check {'-' if check is None else 'passed' if check.passed else 'FAILED'}, final error {error:.3f} deg"
            + ("" if result.success else f": {result.status[:200]}"),
            flush=True,
        )
    t = np.array(times)
    n = len(t)
    print(
        f"searched {searched}/{n}, passed the check {checked}/{n}, planned (check and within 2 deg) {planned}/{n}; "
        f"time mean {t.mean():.1f} s, median {np.median(t):.1f} s, p90 {np.percentile(t, 90):.1f} s, "
        f"max {t.max():.1f} s"
    )


if __name__ == "__main__":
    main()
