"""Plans of the paper's goals by this tree and by another checkout, compared array by array:
how many are bit-identical, and the largest difference in x, q and the forces otherwise.

    python scripts/compare_plans.py --against /path/to/other/checkout [--goals 60] [--seed 0]

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
from trajectotree.experiments.sweep import sample_goals
from trajectotree.planning.planners import plan
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables

out, goals, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
config = Config()
scene, tables = build_scene(config.scene), GraspTables()
for k, goal in enumerate(sample_goals(60, seed)[:goals]):
    result = plan(goal=float(goal), config=config, scene=scene, segment_workers=1, grasp_tables=tables)
    arrays = {} if result.trajectory is None else {n: getattr(result.trajectory, n) for n in TRAJECTORY_ARRAYS}
    np.savez(f"{out}/{k}.npz", success=result.success, **arrays)
"""


def plan_all(tree: Path, out: Path, goals: int, seed: int) -> None:
    out.mkdir()
    env = {**os.environ, "PYTHONPATH": str(tree)}
    # run in `tree`: `python -c` puts the working directory first on sys.path, so run from this checkout's
    # root both children would import this tree and compare it with itself
    subprocess.run([sys.executable, "-c", CHILD, str(out), str(goals), str(seed)], env=env, cwd=tree, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, type=Path, help="the other checkout's root")
    parser.add_argument("--goals", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mine, theirs = Path(tmp) / "this", Path(tmp) / "other"
        plan_all(ROOT, mine, args.goals, args.seed)
        plan_all(args.against.resolve(), theirs, args.goals, args.seed)
        identical, worst, succeeded = 0, {"x": 0.0, "q": 0.0, "forces": 0.0}, [0, 0]
        for k in range(args.goals):
            a, b = np.load(mine / f"{k}.npz"), np.load(theirs / f"{k}.npz")
            succeeded = [succeeded[0] + bool(a["success"]), succeeded[1] + bool(b["success"])]
            if sorted(a.files) != sorted(b.files) or any(a[n].shape != b[n].shape for n in a.files):
                print(f"goal {k}: different arrays or shapes")
                continue
            if all(np.array_equal(a[n], b[n]) for n in a.files):
                identical += 1
                continue
            for key, names in (("x", ("x",)), ("q", ("q",)), ("forces", ("lambda_n", "lambda_t", "f_W"))):
                worst[key] = max([worst[key]] + [float(np.max(np.abs(a[n] - b[n]))) for n in names if n in a.files])
        print(
            f"{identical}/{args.goals} plans bit-identical; largest difference otherwise: x {worst['x']:.3g}, "
            f"q {worst['q']:.3g} rad, forces {worst['forces']:.3g} N; successful (physics check passed): "
            f"this {succeeded[0]}/{args.goals}, other {succeeded[1]}/{args.goals}"
        )


if __name__ == "__main__":
    main()
