"""Replanning latency during execution (executor grasp-replan), and the open-loop path beside it.

Plans each goal once (or loads the plans of --plan-dirs), executes it closed loop with replanning in a
world of friction --sim-mu and prints per goal the replans (time, reason, friction assumed, latency,
outcome), then the drops and the latency (measured state in, first segment ready: the time the hand
holds) median and p95 over every replan, and over those that gave a plan.

--compare TREE (a git worktree of an older trajectotree, e.g. main before the replanner was a system)
executes the same saved plans (--plan-dirs) with that tree's code too, in the same run: each plan in a
subprocess per tree (PYTHONPATH=TREE, or this tree), the trees alternating plan by plan so that a busy
machine slows both alike; then the latency of each, side by side. Only the public API runs in them
(trajectotree.load_plan, run_simulation), so any tree that replans takes part: executor grasp-replan, or
the older run_simulation(replan=True) of the trees before the executor was one typed value.

Then, unless --replan-only, the open-loop path on the goals: planning (search + every segment at
once, the default) and the open-loop execution, medians of wall-clock times (--open-loop-only: that
part alone)."""

import argparse
import inspect
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

GOALS = (2.95, -2.61, 1.57, -0.77, 0.05, -1.40, 2.20, -3.10)  # goals no default was tuned on
HERE = Path(__file__).resolve().parents[1]  # this tree


def replanning_keywords(run_simulation) -> dict:
    """run_simulation's keywords for replanning: the executor, or the older trees' replan flag."""
    if "executor" in inspect.signature(run_simulation).parameters:
        return {"executor": "grasp-replan"}
    return {"replan": True}


def replanned_runs(plans: list, sim_mu: float) -> list[dict]:
    """Each plan executed with replanning: {goal, dropped, mae_theta, final_theta, replans: [event JSON]}."""
    import trajectotree as tt

    runs = []
    for result in plans:
        if not result.success:
            runs.append({"goal": result.goal, "planned": False, "status": result.status})
            continue
        run = tt.run_simulation(plan=result, sim_mu=sim_mu, **replanning_keywords(tt.run_simulation))
        runs.append(
            {
                "goal": result.goal,
                "planned": True,
                "dropped": bool(run.dropped),
                "mae_theta": float(run.mae_theta),
                "final_theta": float(run.final_error[2]),
                "replans": [e.to_json() for e in run.replans],
            }
        )
    return runs


def print_runs(runs: list[dict], sim_mu: float, label: str) -> None:
    """Per goal its replans, then the drops, the outcomes and the latency median and p95."""
    latencies, planned, drops, outcomes = [], [], 0, {}
    for run in runs:
        if not run["planned"]:
            print(f"goal {run['goal']:+.2f}: no plan ({run['status']})")
            continue
        drops += run["dropped"]
        print(
            f"goal {run['goal']:+.2f}: {'DROPPED' if run['dropped'] else 'held'}, MAE theta {run['mae_theta']:.4f} "
            f"rad, final theta error {run['final_theta']:+.3f} rad"
        )
        for e in run["replans"]:
            latencies.append(e["latency_s"])
            outcomes[e["outcome"]] = outcomes.get(e["outcome"], 0) + 1
            if e["planned"]:
                planned.append(e["latency_s"])
            print(
                f"  t {e['time_s']:5.2f} s {e['reason']:9s} mu {e['mu']:.3f} latency {e['latency_s']:5.3f} s: "
                f"{e['outcome']}"
            )
    print(f"{label}: {drops} of {len(runs)} dropped at sim mu {sim_mu:g}")
    print(f"{label}: outcomes " + ", ".join(f"{o} {n}" for o, n in outcomes.items()))
    for name, values in (("every replan", latencies), ("replans with a new plan", planned)):
        if values:
            print(
                f"{label}: replan latency over {len(values)} ({name}): median {np.median(values):.3f} s, "
                f"p95 {np.percentile(values, 95):.3f} s, max {np.max(values):.3f} s"
            )
    print_split([e for run in runs if run["planned"] for e in run["replans"]], label)


def print_split(events: list[dict], label: str) -> None:
    """Per outcome, medians of the latency and its parts: the search, the first segment's attempts (their
    builds and IPOPT solves; the iterations) and the rest (the start's checks, the pool, the physics check).
    Events of a tree that does not record a part count it as 0."""
    for outcome in sorted({e["outcome"] for e in events}):
        rows = [e for e in events if e["outcome"] == outcome]
        part = {
            name: np.array([e.get(name) or 0.0 for e in rows]) for name in ("latency_s", "search_s", "first_segment_s")
        }
        other = part["latency_s"] - part["search_s"] - part["first_segment_s"]
        iterations = np.median([e.get("first_segment_iterations") or 0 for e in rows])
        print(
            f"{label}: {outcome} ({len(rows)}): latency {np.median(part['latency_s']):.3f} s = search "
            f"{np.median(part['search_s']):.3f} + first segment {np.median(part['first_segment_s']):.3f} "
            f"({iterations:.0f} iterations) + other {np.median(other):.3f} (medians)"
        )


def runs_in(tree: Path, plan_dir: str, sim_mu: float) -> list[dict]:
    """replanned_runs of the plan in `plan_dir` with the code of `tree`, in a process of its own."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    command = [sys.executable, __file__, "--emit-json", "--sim-mu", str(sim_mu), "--plan-dirs", plan_dir]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare(plan_dirs: list[str], old: Path, sim_mu: float) -> None:
    """Both trees on the same plans, alternating plan by plan; each tree's runs, then their latency."""
    runs = {HERE: [], old: []}
    for plan_dir in plan_dirs:
        for tree in runs:
            runs[tree].extend(runs_in(tree, plan_dir, sim_mu))
    for tree, label in ((old, f"old ({old})"), (HERE, f"new ({HERE})")):
        print_runs(runs[tree], sim_mu, label)


def open_loop(goals, repeats: int) -> None:
    import trajectotree as tt

    plan_s, sim_s = [], []
    for goal in goals:
        for _ in range(repeats):
            t0 = time.perf_counter()
            result = tt.plan(goal=goal)
            plan_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        tt.run_simulation(plan=result)
        sim_s.append(time.perf_counter() - t0)
    where = Path(tt.__file__).parent.parent
    print(
        f"open loop ({where}): plan median {np.median(plan_s):.3f} s over {len(plan_s)}, "
        f"simulation median {np.median(sim_s):.3f} s over {len(sim_s)}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sim-mu", type=float, default=0.4, help="friction of the simulated world (plans: 0.7)")
    parser.add_argument("--goals", type=float, nargs="+", default=GOALS, metavar="RAD")
    parser.add_argument("--plan-dirs", nargs="+", metavar="DIR", help="saved plans to execute instead of --goals")
    parser.add_argument("--compare", type=Path, metavar="TREE", help="also run the plans with TREE's code")
    parser.add_argument("--open-loop-only", action="store_true", help="only the open-loop part (public API)")
    parser.add_argument("--replan-only", action="store_true", help="only the replanning part")
    parser.add_argument("--repeats", type=int, default=1, help="open-loop plans per goal")
    parser.add_argument("--emit-json", action="store_true", help=argparse.SUPPRESS)  # --compare's subprocesses
    args = parser.parse_args()
    if args.compare is not None and not args.plan_dirs:
        parser.error("--compare needs --plan-dirs: both trees execute the same saved plans")
    if args.emit_json:
        import trajectotree as tt

        print(json.dumps(replanned_runs([tt.load_plan(d) for d in args.plan_dirs], args.sim_mu)))
        return
    if not args.open_loop_only:
        if args.compare is not None:
            compare(args.plan_dirs, args.compare.resolve(), args.sim_mu)
        else:
            import trajectotree as tt

            plans = (
                [tt.load_plan(d) for d in args.plan_dirs] if args.plan_dirs else [tt.plan(goal=g) for g in args.goals]
            )
            print_runs(replanned_runs(plans, args.sim_mu), args.sim_mu, "this tree")
    if not args.replan_only:
        open_loop(args.goals, args.repeats)


if __name__ == "__main__":
    main()
