"""Benchmark of execution wall time per controller, in one process: simulates one
full-length plan (9 segments, 10.8 s plus the settle time) with the grasp controller
and with eq. 20 (`paper`), alternating, REPEATS times each, and prints each
controller's median wall time of `Simulator.AdvanceTo` (SimResult.sim_time_s) and the
ratio grasp / paper. Target: the grasp controller at most 1.5x eq. 20.

PLAN_DIR is a folder from `trajectotree plan` (the default plan is a 9-segment
TrajectoTree plan of goal 0.9 rad, made here first, ~15 s). --profile prints the
grasp run's top functions (cProfile, cumulative time).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys

import numpy as np

from trajectotree.config import Config
from trajectotree.config.executor import Executor
from trajectotree.execution.reference import Reference, reference_from_arrays, reference_from_plan
from trajectotree.execution.simulate import simulate_reference
from trajectotree.scene.plant import build_scene

CONTROLLERS = ("grasp", "paper")


def load_reference(plan_dir: str | None, goal: float) -> tuple[Reference, Config]:
    """The plan in plan_dir, or a fresh default TrajectoTree plan of `goal`."""
    if plan_dir is not None:
        from trajectotree.cli.simulate_cmd import read_plan_dir

        arrays, config = read_plan_dir(plan_dir)
        return reference_from_arrays(arrays, build_scene(config.scene)), config
    from trajectotree.planning.planners import plan

    config = Config()
    scene = build_scene(config.scene)
    result = plan(scene=scene, goal=goal, method="trajectotree", config=config)
    if result.trajectory is None:
        sys.exit(f"planning goal {goal} produced no trajectory ({result.status})")
    return reference_from_plan(result, scene), config


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("plan_dir", nargs="?", metavar="PLAN_DIR", help="plan folder (default: plan goal --goal)")
    parser.add_argument("--goal", type=float, default=0.9, help="goal of the default plan, rad (default 0.9)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per controller (default 3)")
    parser.add_argument("--profile", action="store_true", help="profile one grasp run (cProfile)")
    args = parser.parse_args()
    reference, config = load_reference(args.plan_dir, args.goal)
    print(
        f"plan: {reference.duration:.1f} s, {len(reference.t)} knots; simulated {reference.duration:.1f} + "
        f"{config.sim.settle_time:.1f} s at time step {config.sim.time_step:g} s, grasp control at "
        f"{config.controller.rate_hz:g} Hz"
    )
    times = {c: [] for c in CONTROLLERS}
    for _ in range(args.repeats):
        for controller in CONTROLLERS:  # alternating, so a change in machine load hits both
            result = simulate_reference(reference, config, executor=Executor(controller))
            times[controller].append(result.sim_time_s)
            print(
                f"  {controller:5s} {result.sim_time_s:6.2f} s  dropped {result.dropped}  "
                f"MAE theta {np.degrees(result.mae_theta):.2f} deg",
                flush=True,
            )
    medians = {c: float(np.median(t)) for c, t in times.items()}
    for c in CONTROLLERS:
        print(
            f"{c:5s} median {medians[c]:6.2f} s over {args.repeats} runs "
            f"({reference.duration + config.sim.settle_time:.1f} s simulated)"
        )
    print(f"ratio grasp / paper: {medians['grasp'] / medians['paper']:.2f} (target <= 1.5)")
    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(simulate_reference, reference, config, executor=Executor.GRASP)
        pstats.Stats(profiler).sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    main()
