"""The contact search of two checkouts side by side: same contact plans, and how long each takes.

In one run, `find_contact_plan` on the paper's goals (seed --seed, --goals of them, the initial-grasp tables
built once per process, as scripts/bench_search.py times it) and then on replan-like starts: from a middle
node of every few plans (of the old tree), the object nudged by (0.5 mm, -0.5 mm, 0.004 rad) so that the
contacts come off the grid as a measured state's do, at scene.mu 0.4 and 0.49 (the friction estimates a
replan at 0.4 or 0.7 x 0.7 plans with), searched as the replanner's planner does (planning.start.start_config,
the scene rebuilt at the start pose; search.time_budget_s --budget, the full 30 s by default so that no search
is cut short by a slower machine). Each tree runs in its own worker process (PYTHONPATH=TREE), the two
alternating case by case so that a busy machine slows both alike. Prints each case's wall and CPU seconds,
then per set the medians, means and their ratios old / new, and how many cases gave identical answers
(every field of every node, success, the refusal, expansions, children and roots searched).

    python scripts/compare_search.py --old /tmp/old_checkout [--goals 60] [--starts 12]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # this checkout
NUDGE = (0.0005, -0.0005, 0.004)  # m, m, rad: the start's object pose off the plan's node
START_MUS = (0.4, 0.49)


def worker() -> None:
    """Answers one JSON case per stdin line with one JSON line (this process's PYTHONPATH tree)."""
    from trajectotree.config import Config, SearchConfig
    from trajectotree.planning.start import StartRefused, start_config
    from trajectotree.scene.plant import build_scene
    from trajectotree.search.initial_grasp import GraspTables
    from trajectotree.search.tree import find_contact_plan
    from trajectotree.start import StartState

    scene, tables = build_scene(), GraspTables()
    find_contact_plan(scene, 1.0, SearchConfig(), tables)  # imports, solvers, the tables
    for line in sys.stdin:
        case = json.loads(line)
        if case["kind"] == "goal":
            args = (scene, case["goal"], SearchConfig(), tables)
        else:
            config = Config()
            config = dataclasses.replace(
                config,
                scene=dataclasses.replace(config.scene, mu=case["mu"]),
                search=dataclasses.replace(config.search, time_budget_s=case["budget"]),
            )
            try:
                config = start_config(scene, StartState(object_pose=tuple(case["pose"]), q=tuple(case["q"])), config)
            except StartRefused as refused:
                print(json.dumps({"refused": str(refused)}), flush=True)
                continue
            args = (build_scene(config.scene), case["goal"], config.search)
        t0, c0 = time.perf_counter(), time.process_time()
        plan = find_contact_plan(*args)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        answer = {
            "success": plan.success,
            "refusal": None if plan.success else str(plan.refusal),
            "nodes": [n.to_json() for n in plan.nodes] if plan.success else [],
            "counts": [plan.stats.expanded, plan.stats.generated, plan.stats.initial_grasps_searched],
        }
        print(json.dumps({"answer": answer, "wall": wall, "cpu": cpu}), flush=True)


def start_worker(tree: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree))
    return subprocess.Popen(
        [sys.executable, os.path.abspath(__file__), "--worker"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd="/",  # no checkout on the path but the one asked for
    )


def ask(workers: dict, case: dict) -> dict:
    out = {}
    for name, process in workers.items():
        process.stdin.write(json.dumps(case) + "\n")
        process.stdin.flush()
        out[name] = json.loads(process.stdout.readline())
    return out


def replan_starts(goal_rows, count: int, budget: float) -> list[dict]:
    """Replan-like start cases from every few of the old tree's plans (module doc)."""
    starts = []
    for k, (case, answers) in enumerate(goal_rows[:: max(1, len(goal_rows) // count)][:count]):
        nodes = answers["old"]["answer"]["nodes"]
        if len(nodes) < 3:
            continue
        node = nodes[len(nodes) // 2 - k % 2]
        pose = (np.array(node["object_pose"]) + NUDGE).tolist()
        starts += [
            {"kind": "start", "goal": case["goal"], "pose": pose, "q": node["q"], "mu": mu, "budget": budget}
            for mu in START_MUS
        ]
    return starts


def summary(label: str, rows) -> None:
    timed = [answers for _, answers in rows if "wall" in answers["old"]]
    for what in ("wall", "cpu"):
        old, new = (np.array([a[name][what] for a in timed]) for name in ("old", "new"))
        print(
            f"{label} ({len(timed)} searched), {what} s: old median {np.median(old):.3f} mean {old.mean():.3f} "
            f"max {old.max():.2f}; new median {np.median(new):.3f} mean {new.mean():.3f} max {new.max():.2f}; "
            f"old / new: median {np.median(old) / np.median(new):.2f}x, mean {old.mean() / new.mean():.2f}x, "
            f"per case median {np.median(old / new):.2f}x"
        )
    same = sum(a["old"].get("answer", a["old"]) == a["new"].get("answer", a["new"]) for _, a in rows)
    print(f"{label}: identical answers {same}/{len(rows)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--old", help="the other checkout's root")
    parser.add_argument("--goals", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--starts", type=int, default=12, help="plans to start replan-like searches from")
    parser.add_argument("--budget", type=float, default=30.0, help="s, the starts' search.time_budget_s")
    parser.add_argument("--out", help="JSON file for every case and answer")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker()
        return
    if not args.old:
        parser.error("--old is required")
    from trajectotree.experiments.sweep import sample_goals

    workers = {"old": start_worker(args.old), "new": start_worker(str(HERE))}
    goal_rows = []
    for goal in sample_goals(args.goals, args.seed):
        case = {"kind": "goal", "goal": float(goal)}
        goal_rows.append((case, ask(workers, case)))
        print(f"goal {goal:+.3f}: " + ", ".join(f"{k} {v['wall']:.3f} s" for k, v in goal_rows[-1][1].items()))
    start_rows = []
    for case in replan_starts(goal_rows, args.starts, args.budget):
        start_rows.append((case, ask(workers, case)))
        times = ", ".join(
            f"{k} {v['wall']:.3f} s" if "wall" in v else f"{k} refused" for k, v in start_rows[-1][1].items()
        )
        print(f"start toward {case['goal']:+.3f} at mu {case['mu']}: {times}")
    for process in workers.values():
        process.stdin.close()
        process.wait()
    if args.out:
        Path(args.out).write_text(json.dumps(goal_rows + start_rows))
    summary("goals", goal_rows)
    summary("replan-like starts", start_rows)


if __name__ == "__main__":
    main()
