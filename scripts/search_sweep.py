"""The paper's search experiment: the contact-sequence planner on 60 goal rotations drawn
uniformly from [-pi, pi] (seed 0, N = 10 by default). Prints each goal's outcome, then the
success rate and the median and max search time."""

from __future__ import annotations

import argparse

import numpy as np

from trajectotree.cli.common import add_config_options, config_from_args
from trajectotree.scene import build_scene
from trajectotree.search import find_contact_plan
from trajectotree.sweep import sample_goals


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--goals", type=int, default=60, help="number of goals")
    parser.add_argument("--seed", type=int, default=0, help="goal sampling seed")
    add_config_options(parser)
    args = parser.parse_args()
    config = config_from_args(args)
    scene = build_scene(config.scene)
    plans = [find_contact_plan(scene, goal, config.search) for goal in sample_goals(args.goals, args.seed)]
    for plan in plans:
        s = plan.stats
        print(f"goal {plan.goal:+.3f}  {'ok  ' if plan.success else 'FAIL'}  {s.time_s:.3f} s  "
              f"expanded {s.expanded:4d}  LP {s.lp_calls:4d}  IK {s.ik_calls:4d}  {plan.reason}")
    times = np.array([p.stats.time_s for p in plans])
    found = sum(p.success for p in plans)
    print(f"success {found}/{len(plans)} ({100.0 * found / len(plans):.0f}%), N = {config.search.num_nodes}, "
          f"seed {args.seed}; search time median {np.median(times):.3f} s, max {times.max():.3f} s")


if __name__ == "__main__":
    main()
