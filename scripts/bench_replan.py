"""Replanning latency during execution (simulate --replan), and the open-loop path beside it.

Plans each goal once (or loads the plans of --plan-dirs), executes it closed loop with replanning in a
world of friction --sim-mu and prints per goal the replans (time, reason, friction assumed, latency,
outcome), then the drops and the latency (measured state in, first segment ready: the time the hand
holds) median and p95 over every replan, and over those that gave a plan. Then the open-loop path on
the same goals: planning (search + every segment at once, the default) and the open-loop execution,
medians of wall-clock times. --open-loop-only prints only that part with the public API alone, so the
same script run on an older tree (PYTHONPATH=OLD_TREE) measures the old code beside the new.
All in this one run."""

import argparse
import time
from pathlib import Path

import numpy as np

import trajectotree as tt

GOALS = (2.95, -2.61, 1.57, -0.77, 0.05, -1.40, 2.20, -3.10)  # goals no default was tuned on


def plans(args) -> list:
    if args.plan_dirs:
        return [tt.load_plan(d) for d in args.plan_dirs]
    return [tt.plan(goal=goal) for goal in args.goals]


def replanning(results: list, sim_mu: float) -> None:
    from trajectotree.results import ReplanOutcome

    latencies, planned, drops, outcomes = [], [], 0, {}
    for result in results:
        if not result.success:
            print(f"goal {result.goal:+.2f}: no plan ({result.status})")
            continue
        run = tt.run_simulation(plan=result, sim_mu=sim_mu, executor="grasp-replan")
        drops += run.dropped
        print(
            f"goal {result.goal:+.2f}: {'DROPPED' if run.dropped else 'held'}, MAE theta {run.mae_theta:.4f} rad, "
            f"final theta error {run.final_error[2]:+.3f} rad"
        )
        for e in run.replans:
            latencies.append(e.latency_s)
            outcomes[e.outcome] = outcomes.get(e.outcome, 0) + 1
            if e.planned:
                planned.append(e.latency_s)
            holds = ""
            if e.planned:
                holds = f", whole plan {e.compute_s:.2f} s, segments ready " + " ".join(
                    f"{r:.2f}" for r in e.segment_ready_s
                )
            print(
                f"  t {e.time_s:5.2f} s {e.reason.name.lower():9s} mu {e.mu:.3f} latency {e.latency_s:5.3f} s "
                f"(search {e.search_s:.3f} s): "
                f"{e.outcome.name.lower()}{holds}" + ("" if e.planned else f" ({e.status[:80]})")
            )
    print(f"{drops} of {len(results)} dropped at sim mu {sim_mu:g}")
    print("outcomes: " + ", ".join(f"{o.name.lower()} {n}" for o, n in outcomes.items() if o in ReplanOutcome))
    for name, values in (("every replan", latencies), ("replans with a new plan", planned)):
        if values:
            print(
                f"replan latency over {len(values)} ({name}): median {np.median(values):.3f} s, "
                f"p95 {np.percentile(values, 95):.3f} s, max {np.max(values):.3f} s"
            )


def open_loop(goals, repeats: int) -> None:
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
    parser.add_argument("--open-loop-only", action="store_true", help="only the open-loop part (public API)")
    parser.add_argument("--replan-only", action="store_true", help="only the replanning part")
    parser.add_argument("--repeats", type=int, default=1, help="open-loop plans per goal")
    args = parser.parse_args()
    if not args.open_loop_only:
        replanning(plans(args), args.sim_mu)
    if not args.replan_only:
        open_loop(args.goals, args.repeats)


if __name__ == "__main__":
    main()
