"""The paper's search experiment: the contact-sequence planner on 60 goal rotations drawn
uniformly from [-pi, pi] (seed 0, trajectotree.experiments.sweep.sample_goals; N = 10 by default), or
on an evenly spaced grid of goals (--grid K: K goals from -pi to pi). Prints each goal's
outcome (initial grasp, how many candidate grasps were searched, the largest friction any
switching stance needs), then the success rate and the median and max search time.

    python scripts/search_sweep.py                                  # 60 paper goals, defaults
    python scripts/search_sweep.py --grid 73                        # -pi..pi every 5 degrees
    python scripts/search_sweep.py --box-size 0.24 0.12 --mu 0.5    # another box and friction
    python scripts/search_sweep.py --friction-safety 1.0            # the paper's friction (no margin)
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from trajectotree.cli.common import add_config_options, config_from_args
from trajectotree.experiments.sweep import sample_goals
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import GraspTables
from trajectotree.search.tree import find_contact_plan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goals", type=int, default=60, help="number of goals")
    parser.add_argument("--seed", type=int, default=0, help="goal sampling seed")
    parser.add_argument("--grid", type=int, metavar="K", help="K evenly spaced goals in [-pi, pi] instead")
    parser.add_argument("--friction-safety", type=float, help="search.friction_safety, in (0, 1]")
    add_config_options(parser)
    args = parser.parse_args()
    config = config_from_args(args)
    if args.friction_safety is not None:
        config = dataclasses.replace(
            config, search=dataclasses.replace(config.search, friction_safety=args.friction_safety)
        )
    scene = build_scene(config.scene)
    goals = np.linspace(-np.pi, np.pi, args.grid) if args.grid else sample_goals(args.goals, args.seed)
    plans, tables = [], GraspTables()  # the initial grasps ranked once for all goals
    for goal in goals:
        plan = find_contact_plan(scene, float(goal), config.search, tables)
        plans.append(plan)
        s = plan.stats
        stance = max((n.stance_required_mu for n in plan.nodes if n.stance_required_mu is not None), default=np.nan)
        grasp = " ".join(f"{v:.2f}" for v in plan.nodes[0].arclengths) if plan.success else "-"
        print(
            f"goal {plan.goal:+.3f}  {'ok  ' if plan.success else 'FAIL'}  {s.time_s:.3f} s  "
            f"grasps {s.initial_grasps_searched:2d}/{s.initial_grasp_candidates}  expanded {s.expanded:5d}  "
            f"initial [{grasp}]  max stance mu {stance:.3f}  {plan.reason}",
            flush=True,
        )
    times = np.array([p.stats.time_s for p in plans])
    found = sum(p.success for p in plans)
    c = config.scene
    print(
        f"success {found}/{len(plans)} ({100.0 * found / len(plans):.0f}%), box {c.box_width:g} x {c.box_height:g} m, "
        f"mu {c.mu:g}, mu_plan {plans[0].mu_plan:.3g}, N = {sorted({len(p.nodes) for p in plans if p.success})}, "
        f"{'grid' if args.grid else f'seed {args.seed}'}; search time median {np.median(times):.3f} s, "
        f"max {times.max():.3f} s"
    )


if __name__ == "__main__":
    main()
