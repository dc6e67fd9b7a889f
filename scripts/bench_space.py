"""Planning in space on fingerpro4 (search + the keyframes programs in space): of `--goals` orientations uniform
over SO(3) (seed 0, the cube's position unchanged), or of the 23 axis-aligned ones (`--axis-aligned`: the
cube's 24 rotations but the identity, MuJoCo MPC's task), how many are planned, pass the 3D physics check and
end within 2 deg of their goal, and the planning time per goal (mean, median, p90 over all goals, wall time of
plan_space: the search, then the segments at once on the segment pool). One process; the machine's load
average is printed before and after, and per goal the CPU seconds of the segments' solves (summed over the
workers), which other processes on a shared machine disturb less than the wall time.

    python scripts/bench_space.py                # 30 goals, seed 0, one worker per core
    python scripts/bench_space.py --goals 5 --first 2
    python scripts/bench_space.py --axis-aligned
    python scripts/bench_space.py --workers 1    # the segments one after another in this process
    python scripts/bench_space.py --goals 3 --cito 3   # and general CITO (cito, cito-warm) on the first 3 goals
    python scripts/bench_space.py --goals 3 --cito 3 --cito-methods cito   # cold CITO only

With `--cito N` the first N goals are also planned by general CITO in space (planning.spatial.plan_space_cito: cold
from the search's best initial grasp, and warm from the TrajectoTree plan just made, whose time its total includes),
in the same run, and the ratio of the medians of their planning times over TrajectoTree's is printed.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scipy.spatial.transform import Rotation

from trajectotree.config import Config
from trajectotree.experiments.sweep import axis_aligned_goals
from trajectotree.geometry import quaternion_angle
from trajectotree.planning.spatial import plan_space, plan_space_cito
from trajectotree.scene.spatial import START_POSE, build_space_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--first", type=int, default=0, help="start at this goal of the list")
    parser.add_argument("--axis-aligned", action="store_true", help="the 23 axis-aligned orientations instead")
    parser.add_argument("--workers", type=int, default=None, help="segment workers (default: one per core)")
    parser.add_argument("--cito", type=int, default=0, metavar="N", help="general CITO too on the first N goals")
    parser.add_argument(
        "--cito-methods",
        nargs="+",
        default=["cito", "cito-warm"],
        choices=["cito", "cito-warm"],
        help="which of general CITO's methods --cito runs (default: both)",
    )
    args = parser.parse_args()
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    if args.axis_aligned:
        goals = axis_aligned_goals()
    else:
        goals = Rotation.random(args.goals, random_state=args.seed).as_quat(scalar_first=True)
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}; {os.cpu_count()} cores", flush=True)
    times, searched, checked, planned, cpu = [], 0, 0, 0, []
    baselines = {m: [] for m in args.cito_methods}  # per method, (time s, planned) of the goals CITO ran on
    for k in range(args.first, len(goals)):
        goal = goals[k]
        t0 = time.perf_counter()
        result = plan_space(scene, goal, config, args.workers)
        times.append(time.perf_counter() - t0)
        cpu.append(sum(s["cpu_time_s"] for s in result.segments))
        searched += result.contact_plan.success
        check = result.physics_check
        checked += check is not None and check.passed
        planned += result.success
        angle = np.degrees(quaternion_angle(START_POSE[:4], goal))
        error = np.degrees(result.final_error_rad)
        print(
            f"goal {k:2d}: {angle:5.1f} deg, {'planned' if result.success else 'NOT PLANNED'} in {times[-1]:.1f} s "
            f"(search {result.search_time_s:.1f} s, {len(result.segments)} segments {result.solve_time_s:.1f} s, "
            f"their CPU {cpu[-1]:.1f} s), check {'-' if check is None else 'passed' if check.passed else 'FAILED'}, "
            f"final error {error:.3f} deg" + ("" if result.success else f": {result.status[:200]}"),
            flush=True,
        )
        if k - args.first < args.cito:
            for method, runs in baselines.items():
                run = plan_space_cito(
                    scene, goal, config, method, args.workers, result if method == "cito-warm" else None
                )
                runs.append((run.total_time_s, run.success, times[-1]))
                print(
                    f"  {method}: {'planned' if run.success else 'NOT PLANNED'} in {run.total_time_s:.1f} s (program "
                    f"{run.solve_time_s:.1f} s)" + ("" if run.success else f": {run.status[:200]}"),
                    flush=True,
                )
    t = np.array(times)
    n = len(t)
    print(
        f"searched {searched}/{n}, passed the check {checked}/{n}, planned (check and within 2 deg) {planned}/{n}; "
        f"time mean {t.mean():.1f} s, median {np.median(t):.1f} s, p90 {np.percentile(t, 90):.1f} s, "
        f"max {t.max():.1f} s; segments' CPU per goal mean {np.mean(cpu):.1f} s"
    )
    for method, runs in baselines.items():
        if runs:
            mine, ok, theirs = np.array(runs).T
            print(
                f"{method} on the first {len(runs)} goals: planned {int(ok.sum())}/{len(runs)}, time median "
                f"{np.median(mine):.1f} s against TrajectoTree's {np.median(theirs):.1f} s on the same goals: "
                f"ratio of medians {np.median(mine) / np.median(theirs):.1f}x"
            )
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
