"""Runs TrajectoTree on the paper's goal set (60 goals in [-pi, pi], seed 0) and prints,
per goal, success, IPOPT status and iterations, times, cost and final orientation
error, then a summary: success rate, final-orientation error, mean/median times.
With --baselines K, also plans the first K goals with `cito` and `cito-warm` and
prints their success, time and cost beside TrajectoTree's."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np

from trajectotree.config import Config
from trajectotree.planners import plan
from trajectotree.scene import build_scene
from trajectotree.sweep import sample_goals


def row(result) -> dict:
    final = result.trajectory.x[-1, 2] if result.trajectory is not None else float("nan")
    return {"goal": result.goal, "method": result.method, "success": result.success, "status": result.status,
            "iterations": result.iterations, "search_s": result.search_time_s, "build_s": result.build_time_s,
            "solve_s": result.solve_time_s, "total_s": result.total_time_s, "cost": result.cost,
            "final_error_deg": math.degrees(abs(final - result.goal)),
            "eval_share": _eval_share(result.solver_timing), "violations": dict(result.violations)}


def _eval_share(timing: dict) -> float:
    total = timing.get("ipopt_total_s")
    return timing.get("function_evaluations_s", float("nan")) / total if total else float("nan")


def print_row(i: int, r: dict) -> None:
    print(f"{i:3d} {r['method']:>12s} {r['goal']:+7.3f} {str(r['success']):>5s} {r['iterations']:5d} "
          f"{r['search_s']:6.2f} {r['build_s']:6.2f} {r['solve_s']:7.2f} {r['total_s']:7.2f} {r['cost']:9.3f} "
          f"{r['final_error_deg']:7.2f} {r['eval_share']:6.2f}  {r['status']}", flush=True)


def summarize(rows: list[dict], method: str) -> None:
    rows = [r for r in rows if r["method"] == method]
    if not rows:
        return
    ok = [r for r in rows if r["success"]]
    err = np.array([r["final_error_deg"] for r in ok])
    total = np.array([r["total_s"] for r in rows])
    print(f"{method}: converged {len(ok)}/{len(rows)}; final orientation error (converged): "
          f"max {err.max() if len(err) else float('nan'):.2f} deg, mean {err.mean() if len(err) else float('nan'):.2f} deg, "
          f"within 5 deg: {int(np.sum(err <= 5.0))}/{len(rows)}; total time mean {total.mean():.2f} s, "
          f"median {np.median(total):.2f} s; mean iterations {np.mean([r['iterations'] for r in rows]):.0f}; "
          f"mean cost (converged) {np.mean([r['cost'] for r in ok]) if ok else float('nan'):.3f}")
    if ok:
        worst = {k: max(r["violations"][k] for r in ok) for k in ok[0]["violations"]}
        print(f"  max violation over converged goals: " + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--goals", type=int, default=60, help="number of goals (default 60, the paper's)")
    parser.add_argument("--seed", type=int, default=0, help="goal sampling seed (default 0)")
    parser.add_argument("--baselines", type=int, default=0, metavar="K",
                        help="also plan the first K goals with cito and cito-warm")
    parser.add_argument("--segments", type=int, default=None,
                        help="transition segments N - 1 (default: the config's, 9 as in the paper)")
    args = parser.parse_args()
    config = Config()
    if args.segments is not None:
        config = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=args.segments + 1))
    scene = build_scene(config.scene)
    goals = sample_goals(args.goals, args.seed)
    print("  i       method    goal  succ iters search  build   solve   total      cost err_deg  evals  status")
    rows = []
    t0 = time.perf_counter()
    for i, goal in enumerate(goals):
        methods = ["trajectotree"] + (["cito-warm", "cito"] if i < args.baselines else [])
        for method in methods:
            rows.append(row(plan(scene=scene, goal=float(goal), method=method, config=config)))
            print_row(i, rows[-1])
    print(f"--- {len(goals)} goals, seed {args.seed}, {config.search.num_nodes - 1} segments, "
          f"wall {time.perf_counter() - t0:.0f} s")
    for method in ("trajectotree", "cito-warm", "cito"):
        summarize(rows, method)


if __name__ == "__main__":
    main()
