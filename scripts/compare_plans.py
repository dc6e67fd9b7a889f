"""Plans of the paper's goals (or --goal-list) by this tree and by another checkout, compared array
by array: how many are bit-identical, and the largest difference in x, q and the forces otherwise.

    python scripts/compare_plans.py --against /path/to/other/checkout [--goals 60] [--seed 0]
    python scripts/compare_plans.py --against /path/to/other/checkout --goal-list=-3.05,2.2

Each tree plans in a child process of its own (PYTHONPATH set to it, segments serially, one
grasp table for all goals), the default config (the paper's box and hand); the plan arrays go to
a temporary folder and are compared there.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import sys
import numpy as np
from trajectotree.config import Config
from trajectotree.planning.planners import plan
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables

out, goals = sys.argv[1], [float(g) for g in sys.argv[2].split(",")]
config = Config()
scene, tables = build_scene(config.scene), GraspTables()
for k, goal in enumerate(goals):
    result = plan(goal=goal, config=config, scene=scene, segment_workers=1, grasp_tables=tables)
    arrays = {} if result.trajectory is None else {n: getattr(result.trajectory, n) for n in TRAJECTORY_ARRAYS}
    retries = sum(s["retries"] for s in result.segments or ())
    np.savez(f"{out}/{k}.npz", success=result.success, retries=retries, **arrays)
"""


def plan_all(tree: Path, out: Path, goals: list[float]) -> None:
    out.mkdir()
    env = {**os.environ, "PYTHONPATH": str(tree)}
    # run in `tree`: `python -c` puts the working directory first on sys.path, so run from this checkout's
    # root both children would import this tree and compare it with itself
    listed = ",".join(repr(g) for g in goals)
    subprocess.run([sys.executable, "-c", CHILD, str(out), listed], env=env, cwd=tree, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, type=Path, help="the other checkout's root")
    parser.add_argument("--goals", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--goal-list", help="comma-separated goals (rad), instead of the paper's")
    args = parser.parse_args()
    if args.goal_list:
        goals = [float(g) for g in args.goal_list.split(",")]
    else:
        from trajectotree.experiments.sweep import sample_goals

        goals = [float(g) for g in sample_goals(60, args.seed)[: args.goals]]
    with tempfile.TemporaryDirectory() as tmp:
        mine, theirs = Path(tmp) / "this", Path(tmp) / "other"
        plan_all(ROOT, mine, goals)
        plan_all(args.against.resolve(), theirs, goals)
        identical, worst, succeeded = 0, {"x": 0.0, "q": 0.0, "forces": 0.0}, [0, 0]
        for k, goal in enumerate(goals):
            a, b = np.load(mine / f"{k}.npz"), np.load(theirs / f"{k}.npz")
            succeeded = [succeeded[0] + bool(a["success"]), succeeded[1] + bool(b["success"])]
            retries = f"retries this {int(a['retries'])}, other {int(b['retries'])}"
            if sorted(a.files) != sorted(b.files) or any(a[n].shape != b[n].shape for n in a.files):
                print(f"goal {goal:+.5f}: different arrays or shapes ({retries})")
                continue
            arrays = [n for n in a.files if n not in ("success", "retries")]
            if all(np.array_equal(a[n], b[n]) for n in arrays):
                identical += 1
                print(f"goal {goal:+.5f}: bit-identical ({retries})")
                continue
            print(f"goal {goal:+.5f}: differs; physics check passed this {bool(a['success'])} ({retries})")
            for key, names in (("x", ("x",)), ("q", ("q",)), ("forces", ("lambda_n", "lambda_t", "f_W"))):
                worst[key] = max([worst[key]] + [float(np.max(np.abs(a[n] - b[n]))) for n in names if n in a.files])
        print(
            f"{identical}/{len(goals)} plans bit-identical; largest difference otherwise: x {worst['x']:.3g}, "
            f"q {worst['q']:.3g} rad, forces {worst['forces']:.3g} N; successful (physics check passed): "
            f"this {succeeded[0]}/{len(goals)}, other {succeeded[1]}/{len(goals)}"
        )


if __name__ == "__main__":
    main()
