"""Benchmark of the contact-sequence planner.

Default: in one process, the median search time over the 60 goals of seed 0 (target: under
0.2 s), the per-call medians of its two primitives, the form-closure LP (built once, updated per
call) and one finger's Drake IK (SNOPT); also the one-time cost of ranking the candidate initial
grasps (kept in one GraspTables for every goal, so the search times exclude it).

--cli: what a user sees: `trajectotree search --goal G --json` in a fresh process per goal (the
initial grasps ranked inside each search, every import paid), on the 8 goals of --cli-goals,
--repeats times; prints the median search_time_s and the median wall time of the whole command.
With --compare OLD_TREE (a checkout of the old code, e.g. `git worktree add /tmp/old main`), the
same commands run the old code too (PYTHONPATH=OLD_TREE), old and new alternating goal by goal so
that both see the same machine load, and the script prints both medians and their ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from trajectotree.config import SearchConfig
from trajectotree.experiments.sweep import sample_goals
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.plant import build_scene
from trajectotree.search.grasp import FormClosureLp, grasp_matrix
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.reach import Reachability
from trajectotree.search.tree import find_contact_plan


def lp_times(boundary: ConvexPolygon, mu: float, count: int, rng) -> np.ndarray:
    """Seconds per UpdateCoefficients + Solve of the 4-contact LP on random contacts."""
    lp = FormClosureLp(4, mu)
    out = []
    for _ in range(count):
        p, n = zip(*(boundary.point(s) for s in rng.uniform(0, boundary.perimeter, 4)))
        G = grasp_matrix(np.array(p), np.array(n))
        t0 = time.perf_counter()
        lp.solve(G)
        out.append(time.perf_counter() - t0)
    return np.array(out)


def ik_times(reach: Reachability, count: int, rng) -> np.ndarray:
    """Seconds per Drake IK solve (seeded by the closed form) on reachable contacts."""
    out = []
    while len(out) < count:
        finger, pose = int(rng.integers(4)), (0.0, 0.0, rng.uniform(-np.pi, np.pi))
        s = rng.uniform(0, reach.boundary.perimeter)
        guess = reach.closed_form(pose, finger, s)
        if guess.reachable:
            t0 = time.perf_counter()
            reach._drake_ik(finger, reach.tip_target(pose, s), guess.q)
            out.append(time.perf_counter() - t0)
    return np.array(out)


CLI_GOALS = (2.95, -2.61, 1.57, -0.77, 0.05, -1.40, 2.20, -3.10)  # unseen by the defaults' tuning


def cli_search(goal: float, tree: str) -> dict:
    """One `trajectotree search --goal goal --json` in a fresh process running the checkout
    `tree`'s code: its stats, and the command's wall time."""
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree))
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "trajectotree.cli", "search", "--goal", repr(goal), "--json"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
        cwd="/",  # no checkout on the path but the one asked for
    )
    wall = time.perf_counter() - t0
    data = json.loads(out.stdout)
    return {
        "goal": goal,
        "success": data["success"],
        "search_s": data["stats"]["time_s"],
        "wall_s": wall,
        **data["stats"],
    }


def cli_benchmark(goals, repeats: int, old: str | None) -> None:
    """--cli (module doc): fresh processes, old and new alternating."""
    new_tree = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    trees = {"new": new_tree} | ({} if old is None else {"old": old})
    rows = {name: [] for name in trees}
    for _ in range(repeats):
        for goal in goals:
            for name, tree in trees.items():
                rows[name].append(cli_search(goal, tree))
    median = {}
    for name, found in rows.items():
        search, wall = np.array([r["search_s"] for r in found]), np.array([r["wall_s"] for r in found])
        median[name] = (np.median(search), np.median(wall))
        per_goal = {g: np.median([r["search_s"] for r in found if r["goal"] == g]) for g in goals}
        print(
            f"{name} ({trees[name]}): {sum(r['success'] for r in found)} of {len(found)} found; search_time_s median "
            f"{median[name][0]:.3f} s (per goal: {', '.join(f'{g:+.2f}: {t:.3f}' for g, t in per_goal.items())}); "
            f"command wall time median {median[name][1]:.2f} s; median {np.median([r['expanded'] for r in found]):.0f} "
            "expansions"
        )
    if old is not None:
        print(
            f"old / new: search_time_s {median['old'][0] / median['new'][0]:.2f}x, "
            f"command wall time {median['old'][1] / median['new'][1]:.2f}x "
            f"({len(goals)} goals x {repeats} repeats, alternating, medians measured in this run)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--calls", type=int, default=500, help="LP and IK calls to time")
    parser.add_argument("--cli", action="store_true", help="time the search command in fresh processes")
    parser.add_argument("--cli-goals", type=float, nargs="+", default=CLI_GOALS, metavar="RAD")
    parser.add_argument("--repeats", type=int, default=3, help="--cli: runs of each goal")
    parser.add_argument("--compare", metavar="OLD_TREE", help="--cli: also run this checkout's code")
    args = parser.parse_args()
    if args.cli or args.compare:
        cli_benchmark(args.cli_goals, args.repeats, args.compare)
        return
    scene, config = build_scene(), SearchConfig()
    rng = np.random.default_rng(args.seed)
    lp = lp_times(scene.config.shape, scene.config.mu, args.calls, rng)
    ik = ik_times(Reachability(scene), args.calls, rng)
    t0 = time.perf_counter()
    tables = GraspTables()
    table = tables.get(scene, config)  # cold: built once for these settings
    table_time = time.perf_counter() - t0
    find_contact_plan(scene, 1.0, config, tables)  # warm-up: imports, first solver loads
    plans, cpu = [], []
    for goal in sample_goals(args.goals, args.seed):
        t0 = time.process_time()
        plans.append(find_contact_plan(scene, goal, config, tables))
        cpu.append(time.process_time() - t0)
    times = np.array([p.stats.time_s for p in plans])
    print(f"form-closure LP (update + solve): median {1e6 * np.median(lp):.0f} us over {len(lp)} calls")
    print(f"finger IK (Drake, SNOPT, seeded): median {1e6 * np.median(ik):.0f} us over {len(ik)} calls")
    print(
        f"initial grasp candidates: {len(table.candidates)} ranked of {table.assignments} grid grasps "
        f"in {table_time:.3f} s (once for all goals)"
    )
    print(
        f"search over {len(plans)} goals (seed {args.seed}, N = {sorted({len(p.nodes) for p in plans if p.success})}): "
        f"{sum(p.success for p in plans)} found; median {np.median(times):.3f} s, "
        f"mean {times.mean():.3f} s, max {times.max():.3f} s (target: median < 0.2 s); "
        f"CPU time median {np.median(cpu):.3f} s (this process; excludes waiting for a busy CPU); "
        f"median {np.median([p.stats.expanded for p in plans]):.0f} expansions, "
        f"{np.median([p.stats.lp_calls for p in plans]):.0f} LP and "
        f"{np.median([p.stats.ik_calls for p in plans]):.0f} IK calls per search, "
        f"at most {max(p.stats.initial_grasps_searched for p in plans)} initial grasps searched"
    )


if __name__ == "__main__":
    main()
