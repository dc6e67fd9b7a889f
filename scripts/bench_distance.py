"""Planning time against goal distance: TrajectoTree plans rotations of pi/2, pi, 2 pi, 4 pi and
8 pi (--turns, as multiples of pi) with the default settings, whose segment
count follows from the distance (config.segments_for: 9, 9, 21, 45 and 93 segments), and prints
per goal the search time, the CITO time (the keyframes' segment solves, in parallel on local
processes: total - search) and the total, with whether the plan passed the physics check; then
a least-squares line time = a + b |theta| for each of the three and its R^2, and the ratio of
the longest goal's time to the shortest's beside the ratio of their distances.

--search-only skips CITO. --simulate also executes each plan with the default grasp controller and
prints whether it dropped the object and how far its last simulated pose is from the goal; --out DIR
keeps each goal's plan and run (DIR/<goal>/plan.json, plan.npz, sim.json, sim.npz).

--compare OLD_TREE also runs the old code's search (a checkout, e.g.
`git worktree add /tmp/old main`; PYTHONPATH=OLD_TREE in a subprocess) on the same goals and node
counts (or --old-segment-rotation's), its goal check lifted for the purpose (the old check allows
|theta| <= pi only), within its own search budgets.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

from trajectotree.config import Config, GoalPose, segments_for
from trajectotree.execution.run import run_simulation
from trajectotree.io import save_plan, save_sim
from trajectotree.planning.planners import plan
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

OLD_SEARCH = """
import json, sys, time
import trajectotree.search.tree as tree
from trajectotree.config import SearchConfig
from trajectotree.scene.plant import build_scene
tree.check_goal = lambda goal, name="goal": float(goal)  # the old check stops at pi
goal, nodes = float(sys.argv[1]), int(sys.argv[2])
t0 = time.perf_counter()
found = tree.find_contact_plan(build_scene(), goal, SearchConfig(num_nodes=nodes))
print(json.dumps({"success": found.success, "time_s": time.perf_counter() - t0, "expanded": found.stats.expanded}))
"""


def fit(distance: np.ndarray, seconds: np.ndarray) -> str:
    """The least-squares line seconds = a + b distance, its R^2."""
    b, a = np.polyfit(distance, seconds, 1)
    residual = seconds - (a + b * distance)
    r2 = 1.0 - residual.var() / seconds.var() if seconds.var() > 0 else 1.0
    return f"{a:+.3f} s + {b:.3f} s/rad x |theta| (R^2 {r2:.3f})"


def old_search(tree: str, goal: float, nodes: int) -> dict:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree))
    out = subprocess.run(
        [sys.executable, "-c", OLD_SEARCH, repr(goal), str(nodes)], capture_output=True, text=True, env=env, cwd="/"
    )
    if out.returncode != 0:
        return {"success": False, "time_s": float("nan"), "expanded": -1, "error": out.stderr.strip()[-300:]}
    return json.loads(out.stdout)


def execute(result, goal: float, folder: str | None) -> dict:
    """Runs `result` with the default grasp controller: dropped, the last simulated pose's distance and
    turn from the goal (unwrapped: a turn short is 2 pi off), the simulation's wall time."""
    t0 = time.perf_counter()
    sim = run_simulation(plan=result)
    if folder is not None:
        save_sim(sim, folder)
    final = np.asarray(sim.x[-1], dtype=float)
    start = np.asarray(result.config.scene.initial_pose, dtype=float)
    return {
        "dropped": bool(sim.dropped),
        "position_error_m": float(np.hypot(*(final[:2] - start[:2]))),
        "angle_error_rad": float(final[2] - goal),
        "sim_wall_s": time.perf_counter() - t0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--turns", type=float, nargs="+", default=(0.5, 1, 2, 4, 8), help="goals as multiples of pi")
    parser.add_argument("--sign", type=float, default=1.0, help="+1 or -1: the direction of every goal")
    parser.add_argument("--search-only", action="store_true")
    parser.add_argument("--compare", metavar="OLD_TREE", help="also time the old code's search on the same paths")
    parser.add_argument(
        "--old-segment-rotation",
        type=float,
        metavar="RAD",
        help="--compare: the old search's paths turn this much per segment (e.g. 0.349, pi/9) instead of "
        "having the new node counts",
    )
    parser.add_argument("--simulate", action="store_true", help="execute each plan (default grasp controller)")
    parser.add_argument("--out", metavar="DIR", help="keep each goal's plan (and run) in DIR/<goal>/")
    parser.add_argument("--json", metavar="FILE", help="write the rows")
    args = parser.parse_args()
    config = Config()
    scene = build_scene(config.scene)
    find_contact_plan(scene, 0.3, config.search)  # warm-up: imports and the solvers' first loads
    rows = []
    for k in args.turns:
        goal = args.sign * k * math.pi
        nodes = segments_for(config.search, config.scene.initial_pose, GoalPose(goal)) + 1
        t0 = time.perf_counter()
        if args.search_only:
            found = find_contact_plan(scene, goal, config.search)
            row = {"search_s": found.stats.time_s, "cito_s": float("nan"), "total_s": found.stats.time_s}
            row |= {"success": found.success, "passed": None, "expanded": found.stats.expanded}
        else:
            result = plan(scene=scene, goal=goal, config=config)
            row = {"search_s": result.search_time_s, "total_s": result.total_time_s}
            row |= {"cito_s": result.total_time_s - result.search_time_s, "success": result.success}
            row |= {"passed": None if result.physics_check is None else result.physics_check.passed}
            row |= {"expanded": result.contact_plan.stats.expanded, "status": result.status[:200]}
            folder = None if args.out is None else os.path.join(args.out, f"{goal:+.4f}")
            if folder is not None:
                save_plan(result, folder)
            if args.simulate and result.trajectory is not None:
                row |= execute(result, goal, folder)
        row |= {"goal": goal, "nodes": nodes, "wall_s": time.perf_counter() - t0}
        if args.compare:
            rate = args.old_segment_rotation
            old_nodes = nodes if rate is None else max(round(abs(goal) / rate), 1) + 1
            row["old"] = old_search(args.compare, goal, old_nodes) | {"nodes": old_nodes}
        rows.append(row)
        old = row.get("old")
        print(
            f"goal {goal:+8.3f} rad ({k:g} pi), N = {nodes:3d}: search {row['search_s']:7.3f} s "
            f"({row['expanded']} expansions), CITO {row['cito_s']:7.2f} s, total {row['total_s']:7.2f} s, "
            f"success {row['success']}, physics check {row['passed']}"
            + (
                ""
                if "dropped" not in row
                else f"; executed: dropped {row['dropped']}, final error {row['position_error_m'] * 1e3:.2f} mm "
                f"{math.degrees(row['angle_error_rad']):+.2f} deg ({row['sim_wall_s']:.0f} s)"
            )
            + (
                ""
                if old is None
                else f"; old search (N = {old['nodes']}) {old['time_s']:.2f} s, found {old['success']} "
                f"({old['expanded']} expansions)"
            ),
            flush=True,
        )
    distance = np.array([abs(r["goal"]) for r in rows])
    for key in ("search_s", "cito_s", "total_s"):
        seconds = np.array([r[key] for r in rows])
        if np.all(np.isfinite(seconds)) and len(rows) > 1:
            ratio = seconds[-1] / seconds[0]
            print(
                f"{key[:-2]}: {fit(distance, seconds)}; longest / shortest goal {ratio:.1f}x for "
                f"{distance[-1] / distance[0]:.0f}x the distance"
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2)


if __name__ == "__main__":
    main()
