"""Benchmark of total planning time per method, in one process: plans K goals (default
the paper's 60, seed 0) with each method and prints, per method, the mean and median
total planning time, the search / build / solve split, IPOPT iterations, the share of
IPOPT's time spent in function evaluations, build time relative to solve time, the
success rate (with how many solved plans failed the physics check of trajectotree.physics
and the largest force on a fingertip off the box), the converged plans' final orientation error
and largest constraint violation per group, and TrajectoTree's speedup over each baseline measured
in this run. --json writes every per-goal row.

Targets (issue 7): TrajectoTree mean total <= 3 s, >= 10x faster than CITO, search
median <= 0.2 s, function evaluations <= 30 % of solve time, build <= 10 % of solve.
The baselines take minutes per goal: shorten with --goals.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np
from tqdm import tqdm

from trajectotree.config import Config, load_config
from trajectotree.planners import METHODS, plan
from trajectotree.scene import build_scene
from trajectotree.sweep import sample_goals


def run(goals, methods, config: Config) -> dict[str, list[dict]]:
    """{method: one row of times and counts per goal}."""
    scene = build_scene(config.scene)
    rows = {m: [] for m in methods}
    with tqdm(total=len(goals) * len(methods), file=sys.stderr, desc="planning") as bar:
        for goal in goals:
            for method in methods:
                r = plan(scene=scene, goal=float(goal), method=method, config=config)
                timing, check = r.solver_timing, r.physics_check
                rows[method].append({
                    "goal": r.goal, "success": r.success, "total_s": r.total_time_s, "search_s": r.search_time_s,
                    "build_s": r.build_time_s, "solve_s": r.solve_time_s, "iterations": r.iterations,
                    "cost": r.cost, "function_evaluations_share": timing.get("nlp_function_evaluations_s", np.nan)
                    / timing.get("ipopt_total_s", np.nan),
                    # a solved plan whose arrays fail trajectotree.physics (counted in success = False)
                    "converged": r.converged, "physics_failed": check is not None and not check.passed,
                    "force_at_distance_N": np.nan if check is None else check.force_at_distance_N,
                    # deg, the plan's last orientation vs the goal
                    "final_error_deg": np.nan if r.trajectory is None else math.degrees(abs(r.trajectory.x[-1, 2] - r.goal)),
                    "status": r.status, "violations": dict(r.violations)})
                bar.update()
    return rows


def summary_line(method: str, rows: list[dict]) -> str:
    col = {key: np.array([r[key] for r in rows], dtype=float) for key in rows[0] if key not in ("status", "violations")}
    converged = [r for r in rows if r["converged"]]
    error = col["final_error_deg"][col["converged"] > 0]
    worst = {group: max(r["violations"][group] for r in converged) for group in converged[0]["violations"]} \
        if converged else {}
    return (f"{method:13s} success {int(col['success'].sum())}/{len(rows)} (converged {int(col['converged'].sum())}, "
            f"physics check failed {int(col['physics_failed'].sum())}, max force at a distance "
            f"{np.nanmax(col['force_at_distance_N']):.3g} N)  total mean {col['total_s'].mean():6.2f} s "
            f"median {np.median(col['total_s']):6.2f} s  | search {col['search_s'].mean():.3f} s "
            f"(median {np.median(col['search_s']):.3f})  build {col['build_s'].mean():.2f} s  "
            f"solve {col['solve_s'].mean():6.2f} s  | iterations {col['iterations'].mean():5.1f}  "
            f"function evals {100 * np.nanmean(col['function_evaluations_share']):4.1f} % of IPOPT time  "
            f"build/solve {100 * col['build_s'].sum() / col['solve_s'].sum():4.1f} %  "
            f"cost mean {np.nanmean(col['cost']):.1f}\n"
            f"{'':13s} converged plans: final orientation error max {error.max() if error.size else np.nan:.2f} deg, "
            f"within 5 deg {int(np.sum(error <= 5.0))}/{len(error)}; largest violation "
            + ", ".join(f"{group} {value:.1e}" for group, value in worst.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=60, help="number of goals (default 60, the paper's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default=",".join(METHODS), help=f"comma-separated, from {', '.join(METHODS)}")
    parser.add_argument("--config", help="YAML config (default: the built-in defaults)")
    parser.add_argument("--json", help="also write every per-goal row to this JSON file")
    args = parser.parse_args()
    methods = [m.strip() for m in args.methods.split(",")]
    unknown = [m for m in methods if m not in METHODS]
    if args.goals < 1 or unknown:
        parser.error(f"--goals must be >= 1 (got {args.goals}); methods must be from {', '.join(METHODS)} "
                     f"(unknown: {unknown})")
    config = load_config(args.config) if args.config else Config()
    rows = run(sample_goals(args.goals, args.seed), methods, config)
    print(f"{args.goals} goals, seed {args.seed}, N = {config.search.num_nodes}, M_hat = {config.cito.knots_per_segment}")
    for method in methods:
        print(summary_line(method, rows[method]))
    if "trajectotree" in methods:
        tt = np.array([r["total_s"] for r in rows["trajectotree"]])
        for baseline in (m for m in methods if m != "trajectotree"):
            other = np.array([r["total_s"] for r in rows[baseline]])
            print(f"speedup of trajectotree over {baseline}: {other.mean() / tt.mean():.1f}x (means), "
                  f"{np.median(other) / np.median(tt):.1f}x (medians)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
