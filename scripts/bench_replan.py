"""Replanning latency during execution (simulate --replan): plans each goal once, executes it closed loop
with replanning in a world of friction --sim-mu, and prints per goal the replans (time, reason, friction
assumed, latency, planned or why not), then the drops and the latency median and p95 over every replan
(measured state in, new plan out), all measured in this one run."""

import argparse

import numpy as np

from trajectotree.config import Config
from trajectotree.execution.replan import simulate_replanning
from trajectotree.execution.simulate import Conditions
from trajectotree.planning.planners import plan

GOALS = (2.95, -2.61, 1.57, -0.77, 0.05, -1.40, 2.20, -3.10)  # goals no default was tuned on


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sim-mu", type=float, default=0.4, help="friction of the simulated world (plans: 0.7)")
    parser.add_argument("--goals", type=float, nargs="+", default=GOALS, metavar="RAD")
    args = parser.parse_args()
    config, latencies, drops = Config(), [], 0
    for goal in args.goals:
        result = plan(goal=goal, config=config)
        if not result.success:
            print(f"goal {goal:+.2f}: no plan ({result.status})")
            continue
        run = simulate_replanning(result, config, conditions=Conditions(mu=args.sim_mu))
        drops += run.dropped
        latencies += [e.latency_s for e in run.replans]
        print(f"goal {goal:+.2f}: {'DROPPED' if run.dropped else 'held'}, MAE theta {run.mae_theta:.4f} rad")
        for e in run.replans:
            outcome = "new plan" if e.planned else e.status.split(";")[0][:90]
            print(
                f"  t {e.time_s:5.2f} s {e.reason.name.lower():9s} mu {e.mu:.3f} latency {e.latency_s:5.2f} s: "
                + outcome
            )
    print(f"{drops} of {len(args.goals)} dropped at sim mu {args.sim_mu:g}")
    if latencies:
        print(
            f"replan latency over {len(latencies)} replans: median {np.median(latencies):.2f} s, "
            f"p95 {np.percentile(latencies, 95):.2f} s"
        )


if __name__ == "__main__":
    main()
