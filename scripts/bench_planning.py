"""Benchmark of total planning time per method, in one process: plans K goals (default
the paper's 60, seed 0) with each method and prints, per method, the mean and median
total planning time, the search / build / solve split, IPOPT iterations, the share of
IPOPT's time spent in function evaluations, build time relative to solve time, the
success rate (with how many solved plans failed the physics check of trajectotree.planning.physics
and the largest force on a fingertip off the box), the converged plans' final orientation error
and largest constraint violation per group, and TrajectoTree's speedup over each baseline measured
in this run. --json writes every per-goal row.

TrajectoTree runs in each formulation (--formulations, default both, side by side on the same
goals and contact plans: the joint row reuses the keyframes row's search and counts its time).
For keyframes the script also prints per-segment statistics (IPOPT iterations, time, the slowest
segment, retries) and the parallel speedup: the same plans' segments solved serially in this
process vs on a persistent pool of --workers forked processes (the rows' times) and on a pool
started per plan; the peak resident memory (ru_maxrss) of the worker processes and of this one;
and the start-up of a pool by fork and by spawn.

Targets: TrajectoTree mean total <= 3 s, >= 10x faster than CITO, search
median <= 0.2 s, function evaluations <= 30 % of solve time, build <= 10 % of solve.
The baselines take minutes per goal: shorten with --goals, or give --rows to resume an interrupted run.

Phase timing (--phases, or --compare TREE): plan() as a script calls it (scene and grasp tables kept,
the package's own segment pool), each tree in processes of its own (scripts/plan_timing.py), the
goals in chunks alternating between this checkout and TREE (the code before a change: `git worktree
add DIR REV`), so both see the same machine. Per method and tree: plan()'s wall-clock time (mean,
median, p90, max) split into search, first round, retries, pool and other; the processes' start-up
(imports and scene); with --cli-goals K, the `trajectotree plan` process's wall-clock time on the
first K goals beside plan()'s on the same goals. Goals: --goal-set paper (the 60 of seed 0, or the
first --goals), heldout (8 unseen + 8 of seed 1), both, or --goal-list.

    python scripts/bench_planning.py --goal-set both --compare /work/wt/lean-base --cli-goals 8
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from trajectotree.config import FORMULATIONS, Config, config_to_dict, load_config
from trajectotree.experiments.sweep import sample_goals
from trajectotree.planning.planners import METHODS, plan
from trajectotree.planning.segment_pool import local_pool, prepare_worker
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables


def plan_row(r, search_s: float | None = None) -> dict:
    """One goal's times and counts; search_s: the search time of a contact plan reused from another row."""
    timing, check = r.solver_timing, r.physics_check
    search = r.search_time_s if search_s is None else search_s
    return {
        "goal": r.goal,
        "success": r.success,
        "total_s": r.total_time_s - r.search_time_s + search,
        "search_s": search,
        "build_s": r.build_time_s,
        "solve_s": r.solve_time_s,
        "iterations": r.iterations,
        "cost": r.cost,
        "function_evaluations_share": timing.get("nlp_function_evaluations_s", np.nan)
        / timing.get("ipopt_total_s", np.nan),
        # a solved plan whose arrays fail trajectotree.planning.physics (counted in success = False)
        "converged": r.converged,
        "physics_failed": check is not None and not check.passed,
        "force_at_distance_N": np.nan if check is None else check.force_at_distance_N,
        # deg, the plan's last orientation vs the goal
        "final_error_deg": np.nan if r.trajectory is None else math.degrees(abs(r.trajectory.x[-1, 2] - r.goal)),
        "status": r.status,
        "violations": dict(r.violations),
    }


def segment_row(r, serial, fresh) -> dict:
    """Keyframes: per-segment numbers of `r` (solved on the persistent pool) and the wall-clock
    time of its segment solves vs the same plan's solved serially and on a pool started for it."""
    wall = lambda result: result.total_time_s - result.search_time_s  # noqa: E731 (the segments' wall clock)
    same = all(
        np.array_equal(a, b) for a, b in zip(r.trajectory.arrays().values(), serial.trajectory.arrays().values())
    )
    return {
        "segment_iterations": [s["iterations"] for s in r.segments],
        "segment_time_s": [s["time_s"] for s in r.segments],
        "retries": sum(s["retries"] for s in r.segments),
        "parallel_wall_s": wall(r),
        "serial_wall_s": wall(serial),
        "fresh_pool_wall_s": wall(fresh),
        "serial_identical": same,
        "worker_max_rss_mb": max(a["max_rss_mb"] for s in r.segments for a in s["attempts"]),
    }


def run(
    goals,
    methods,
    config: Config,
    formulations=("keyframes",),
    pool=None,
    workers: int = 2,
    done: dict | None = None,
    on_goal=None,
) -> dict[str, list[dict]]:
    """{method (trajectotree: "trajectotree/<formulation>"): one row of times and counts per goal}.
    done: {goal index: {label: row}} measured before (--rows), not planned again; on_goal(index,
    {label: row}) is called after each goal planned here."""
    scene = build_scene(config.scene)
    tables = GraspTables()  # the initial grasps ranked once for all goals, outside the timed searches
    labels = [m for m in methods if m != "trajectotree"] + [
        f"trajectotree/{f}" for f in formulations if "trajectotree" in methods
    ]
    rows, done = {label: [] for label in labels}, done or {}
    with tqdm(total=len(goals) * len(labels), file=sys.stderr, desc="planning") as bar:
        for index, goal in enumerate(goals):
            if index in done:
                for label in labels:
                    rows[label].append(done[index][label])
                bar.update(len(labels))
                continue
            for method in methods:
                if method != "trajectotree":
                    rows[method].append(
                        plan_row(plan(scene=scene, goal=float(goal), method=method, config=config, grasp_tables=tables))
                    )
                    bar.update()
                    continue
                contact_plan, search_s = None, None
                for formulation in formulations:
                    c = dataclasses.replace(config, cito=dataclasses.replace(config.cito, formulation=formulation))
                    same = dict(scene=scene, goal=float(goal), method=method, config=c, grasp_tables=tables)
                    r = plan(**same, contact_plan=contact_plan, segment_executor=pool)
                    row = plan_row(r, search_s)
                    if contact_plan is None and r.contact_plan.success:
                        contact_plan, search_s = r.contact_plan, r.search_time_s
                    if formulation == "keyframes" and r.trajectory is not None:
                        # the same contact plan solved serially and on a pool per plan
                        serial = plan(**same, contact_plan=contact_plan, segment_workers=1)
                        fresh = plan(**same, contact_plan=contact_plan, segment_workers=workers)
                        row.update(segment_row(r, serial, fresh))
                    rows[f"trajectotree/{formulation}"].append(row)
                    bar.update()
            if on_goal:
                on_goal(index, {label: rows[label][-1] for label in labels})
    return rows


def resume_rows(path: str, header: dict) -> tuple[dict, callable]:
    """--rows: the goals already measured in the JSON-lines file `path` (its first line is the
    run's header: goals, seed, methods, formulations, workers, config; another header is refused),
    and the function that appends one goal's rows, so an interrupted run goes on where it stopped."""
    done = {}
    if os.path.exists(path):
        with open(path) as f:
            lines = [json.loads(line) for line in f if line.strip()]
        if lines and lines[0] != header:
            other = sorted(k for k in header if lines[0].get(k) != header[k])
            sys.exit(f"--rows {path!r} holds a run with other settings ({', '.join(other)} differ); give another file")
        done = {line["index"]: line["rows"] for line in lines[1:]}
    else:
        with open(path, "w") as f:
            f.write(json.dumps(header) + "\n")

    def append(index: int, rows: dict) -> None:
        with open(path, "a") as f:
            f.write(json.dumps({"index": index, "rows": rows}, default=float) + "\n")

    return done, append


def summary_line(method: str, rows: list[dict]) -> str:
    col = {
        key: np.array([r[key] for r in rows], dtype=float)
        for key in rows[0]
        if not isinstance(rows[0][key], (str, dict, list))
    }
    converged = [r for r in rows if r["converged"]]
    error = col["final_error_deg"][col["converged"] > 0]
    worst = (
        {group: max(r["violations"][group] for r in converged) for group in converged[0]["violations"]}
        if converged
        else {}
    )
    return (
        f"{method:22s} success {int(col['success'].sum())}/{len(rows)} (converged {int(col['converged'].sum())}, "
        f"physics check failed {int(col['physics_failed'].sum())}, max force at a distance "
        f"{np.nanmax(col['force_at_distance_N']):.3g} N)  total mean {col['total_s'].mean():6.2f} s "
        f"median {np.median(col['total_s']):6.2f} s  | search {col['search_s'].mean():.3f} s "
        f"(median {np.median(col['search_s']):.3f})  build {col['build_s'].mean():.2f} s  "
        f"solve {col['solve_s'].mean():6.2f} s  | iterations mean {col['iterations'].mean():5.1f} "
        f"median {np.median(col['iterations']):5.1f}  "
        f"function evals {100 * np.nanmean(col['function_evaluations_share']):4.1f} % of IPOPT time  "
        f"build/solve {100 * col['build_s'].sum() / col['solve_s'].sum():4.1f} %  "
        f"cost mean {np.nanmean(col['cost']):.1f}\n"
        f"{'':22s} converged plans: final orientation error max {error.max() if error.size else np.nan:.2f} deg, "
        f"within 5 deg {int(np.sum(error <= 5.0))}/{len(error)}; largest violation "
        + ", ".join(f"{group} {value:.1e}" for group, value in worst.items())
    )


def segment_summary(rows: list[dict]) -> str:
    """Keyframes rows: per-segment iterations and times (means, medians, the slowest segment), the
    retries, the parallel speedup and the workers' peak memory."""
    rows = [r for r in rows if "segment_iterations" in r]
    if not rows:
        return ""
    its = np.concatenate([r["segment_iterations"] for r in rows])
    times = np.concatenate([r["segment_time_s"] for r in rows])
    slowest = max(rows, key=lambda r: max(r["segment_time_s"]))
    wall = {key: np.array([r[key] for r in rows]) for key in ("parallel_wall_s", "serial_wall_s", "fresh_pool_wall_s")}
    serial, pooled, fresh = wall["serial_wall_s"], wall["parallel_wall_s"], wall["fresh_pool_wall_s"]
    return (
        f"{'':22s} segments ({len(its)}): iterations mean {its.mean():.1f} median {np.median(its):.0f} max "
        f"{its.max()}; time mean {times.mean():.2f} s median {np.median(times):.2f} s, slowest {times.max():.2f} s "
        f"(goal {slowest['goal']:+.3f}); per plan the slowest segment's share of the serial time: mean "
        f"{np.mean([max(r['segment_time_s']) / sum(r['segment_time_s']) for r in rows]):.2f}; retries "
        f"{sum(r['retries'] for r in rows)} in {sum(r['retries'] > 0 for r in rows)} plans\n"
        f"{'':22s} segment solves per plan, wall clock: serial mean {serial.mean():.2f} s median "
        f"{np.median(serial):.2f} s; persistent pool mean {pooled.mean():.2f} s median {np.median(pooled):.2f} s "
        f"(speedup {serial.sum() / pooled.sum():.2f}x of the sums, median {np.median(serial / pooled):.2f}x); "
        f"pool per plan mean {fresh.mean():.2f} s median {np.median(fresh):.2f} s "
        f"(speedup {serial.sum() / fresh.sum():.2f}x, median {np.median(serial / fresh):.2f}x); "
        f"parallel arrays identical to serial: {sum(r['serial_identical'] for r in rows)}/{len(rows)}; "
        f"worker peak RSS max {max(r['worker_max_rss_mb'] for r in rows):.0f} MB"
    )


def pool_startup(config: Config, workers: int) -> str:
    """Seconds from starting a pool of `workers` processes to all of them holding the scene, by fork
    (the scene inherited from this process) and by spawn (Drake imported and the scene built anew)."""
    prepare_worker(config.scene)
    out = []
    for method in ("fork", "spawn"):
        t0 = time.perf_counter()
        with local_pool(workers, method) as pool:
            pids = set(pool.map(prepare_worker, [config.scene] * 4 * workers))
            out.append(f"{method} {time.perf_counter() - t0:.2f} s ({len(pids)} processes)")
    return "pool start-up to a ready scene in every worker: " + ", ".join(out)


ROOT = Path(__file__).resolve().parents[1]  # this checkout
# The held-out goals (docs/measurements.md): 8 the project never tuned on and 8 of the sampler's seed 1.
UNSEEN_GOALS = (2.95, -2.61, 1.57, -0.77, 0.05, -1.40, 2.20, -3.10)
PHASES = ("search_s", "first_round_s", "retries_s", "pool_s", "other_s")
CHUNK = 8  # goals per child process; the trees alternate chunk by chunk


def goal_list(args) -> list[float]:
    """The goals of --goal-list, else of --goal-set (paper: the first --goals of seed --seed)."""
    if args.goal_list:
        return [float(g) for g in args.goal_list.split(",")]
    paper = [float(g) for g in sample_goals(args.goals, args.seed)]
    heldout = list(UNSEEN_GOALS) + [float(g) for g in sample_goals(60, 1)[:8]]
    return {"paper": paper, "heldout": heldout, "both": paper + heldout}[args.goal_set]


def child_rows(tree: Path, goals: list[float], methods: list[str]) -> dict:
    """scripts/plan_timing.py over `goals` with the package of `tree`, in a process of its own."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "rows.json"
        # --goals=...: argparse takes a value that starts with a minus sign for an option
        command = [sys.executable, str(ROOT / "scripts" / "plan_timing.py"), f"--goals={','.join(map(str, goals))}"]
        command += ["--methods", ",".join(methods), "--out", str(out)]
        # cwd=tree: the child imports that tree's package whatever this one's path
        subprocess.run(command, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, check=True)
        return json.loads(out.read_text())


def cli_seconds(tree: Path, goal: float) -> float:
    """Wall-clock seconds of one `trajectotree plan --goal` process of `tree`, its output in a temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, "-m", "trajectotree.cli", "plan", "--goal", str(goal), "--out", f"{tmp}/plan"]
        t0 = time.perf_counter()
        subprocess.run(command, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tmp, check=True, capture_output=True)
        return time.perf_counter() - t0


def run_phases(trees: dict[str, Path], goals, methods, cli_goals: int) -> dict[str, dict]:
    """{tree label: {"rows", "start_up_s", "cli_s"}}, the trees alternating chunk by chunk (the CLI goal by goal)."""
    out = {label: {"rows": [], "start_up_s": [], "cli_s": []} for label in trees}
    chunks = [goals[i : i + CHUNK] for i in range(0, len(goals), CHUNK)]
    with tqdm(total=len(chunks) * len(trees) + cli_goals * len(trees), file=sys.stderr, desc="phases") as bar:
        for chunk in chunks:
            for label, tree in trees.items():
                got = child_rows(tree, chunk, methods)
                out[label]["rows"] += got["rows"]
                out[label]["start_up_s"].append(got["start_up_s"])
                bar.update()
        for goal in goals[:cli_goals]:
            for label, tree in trees.items():
                out[label]["cli_s"].append(cli_seconds(tree, goal))
                bar.update()
    return out


def stats(values) -> str:
    a = np.asarray(values, dtype=float)
    return f"{a.mean():6.2f} {np.median(a):6.2f} {np.percentile(a, 90):6.2f} {a.max():6.2f}"


def phase_report(measured: dict[str, dict], methods: list[str], cli_goals: int) -> str:
    """Per method and tree: plan()'s wall clock (mean, median, p90, max), its phases' means and
    p90s, retries, successes; the start-up; the CLI beside plan() on the same goals."""
    lines = [f"{'s: mean median p90 max':>42s}   phase means (p90): " + ", ".join(p[:-2] for p in PHASES)]
    for method in methods:
        for label, got in measured.items():
            rows = [r for r in got["rows"] if r["method"] == method]
            phases = ", ".join(
                f"{np.mean([r[p] for r in rows]):.2f} ({np.percentile([r[p] for r in rows], 90):.2f})" for p in PHASES
            )
            worst = max(rows, key=lambda r: r["wall_s"])
            lines.append(
                f"{method:13s} {label:10s} plan() {stats([r['wall_s'] for r in rows])}   {phases}; "
                f"plans with retries {sum(r['retries'] > 0 for r in rows)}/{len(rows)} "
                f"(with retry rounds {sum(r['retry_rounds'] > 0 for r in rows)}), "
                f"success {sum(r['success'] for r in rows)}/{len(rows)}, "
                f"physics check passed {sum(r['physics_passed'] for r in rows)}/{len(rows)}, "
                f"slowest goal {worst['goal']:+.3f}"
            )
    for label, got in measured.items():
        line = f"{label:10s} start-up (imports and scene) per process: mean {np.mean(got['start_up_s']):.2f} s"
        if cli_goals:
            api = [r["wall_s"] for r in got["rows"] if r["method"] == "trajectotree"][:cli_goals]
            cli = got["cli_s"]
            line += (
                f"; `trajectotree plan` process over the first {cli_goals} goals mean {np.mean(cli):.2f} s vs plan() "
                f"{np.mean(api):.2f} s (CLI - plan() mean {np.mean(np.subtract(cli, api)):.2f} s, "
                f"max {np.max(np.subtract(cli, api)):.2f} s)"
            )
        lines.append(line)
    return "\n".join(lines)


def load_average() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def main_phases(args, methods: list[str]) -> None:
    """--phases / --compare: the phase timing of this checkout (and TREE) over the goals."""
    trees = {"this": ROOT} | ({"compare": Path(args.compare).resolve()} if args.compare else {})
    goals = goal_list(args)
    before = load_average()
    measured = run_phases(trees, goals, methods, args.cli_goals)
    print(f"{len(goals)} goals; trees: " + ", ".join(f"{k} = {v}" for k, v in trees.items()))
    print(f"{before} before, {load_average()} after (2 shared cores)")
    print(phase_report(measured, methods, args.cli_goals))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(measured, f, indent=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=60, help="number of goals (default 60, the paper's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--methods",
        help=f"comma-separated, from {', '.join(METHODS)} (default: all; with --phases: trajectotree)",
    )
    parser.add_argument("--config", help="YAML config (default: the built-in defaults)")
    parser.add_argument("--json", help="also write every per-goal row to this JSON file")
    parser.add_argument(
        "--formulations",
        default=",".join(FORMULATIONS),
        help=f"TrajectoTree's formulations, comma-separated, from {', '.join(FORMULATIONS)}",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count(),
        help="local processes solving the keyframes segments (default: one per core)",
    )
    parser.add_argument(
        "--rows",
        metavar="FILE.jsonl",
        help="append each goal's rows to this file and skip the goals it already holds (a run "
        "of hours can stop and go on; the summary covers every goal in the file)",
    )
    parser.add_argument("--phases", action="store_true", help="the phase timing (see above) instead")
    parser.add_argument("--compare", metavar="TREE", help="phase timing of this checkout beside the package in TREE")
    parser.add_argument("--goal-set", choices=("paper", "heldout", "both"), default="paper")
    parser.add_argument("--goal-list", help="comma-separated goals (rad), instead of --goal-set")
    parser.add_argument("--cli-goals", type=int, default=0, help="phase timing: time the CLI on this many goals")
    args = parser.parse_args()
    phases = args.phases or args.compare
    methods = [m.strip() for m in (args.methods or ("trajectotree" if phases else ",".join(METHODS))).split(",")]
    unknown = [m for m in methods if m not in METHODS]
    formulations = [f.strip() for f in args.formulations.split(",")]
    bad = [f for f in formulations if f not in FORMULATIONS]
    if args.goals < 1 or unknown or bad or args.workers < 1:
        parser.error(
            f"--goals must be >= 1 (got {args.goals}); methods must be from {', '.join(METHODS)} "
            f"(unknown: {unknown}); formulations from {', '.join(FORMULATIONS)} (unknown: {bad}); "
            f"--workers must be >= 1 (got {args.workers})"
        )
    if phases:
        main_phases(args, methods)
        return
    config = load_config(args.config) if args.config else Config()
    header = {
        "goals": args.goals,
        "seed": args.seed,
        "methods": methods,
        "formulations": formulations,
        "workers": args.workers,
        "config": config_to_dict(config),
    }
    done, on_goal = resume_rows(args.rows, header) if args.rows else ({}, None)
    startup = pool_startup(config, args.workers) if "keyframes" in formulations else ""
    with local_pool(args.workers) as pool:
        pool.map(prepare_worker, [config.scene] * args.workers)  # started once, reused by every plan
        rows = run(
            sample_goals(args.goals, args.seed), methods, config, formulations, pool, args.workers, done, on_goal
        )
    print(
        f"{args.goals} goals, seed {args.seed}, N = {config.search.num_nodes or 'from the distance (10 within pi)'}, "
        f"M_hat = {config.cito.knots_per_segment}, {args.workers} segment workers; {startup}"
    )
    for label, label_rows in rows.items():
        print(summary_line(label, label_rows))
        if label == "trajectotree/keyframes":
            print(segment_summary(label_rows))
    tt_labels = [label for label in rows if label.startswith("trajectotree")]
    for label in tt_labels:
        tt = np.array([r["total_s"] for r in rows[label]])
        for baseline in (m for m in rows if m not in tt_labels):
            other = np.array([r["total_s"] for r in rows[baseline]])
            print(
                f"{baseline} / {label} total time: {other.mean() / tt.mean():.1f}x (means), "
                f"{np.median(other) / np.median(tt):.1f}x (medians)"
            )
    print(
        f"peak RSS of this process (search, serial solves, the joint program): "
        f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
