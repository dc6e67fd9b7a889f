"""`trajectotree sweep`: the paper's experiment, random goals x methods, resumable and parallel.

Goals are drawn uniformly in [-pi, pi] from --seed; for a hand in space (--hand fingerpro4) they are
orientations uniform over SO(3) (at most --max-goal from the start), or with --axis-aligned the cube's 23
axis-aligned orientations; its plans execute as the plane's (--simulate, --controllers and --conditions: the
worlds of a sweep in space are nominal, mismatch, push, friction-0.4, mass-x1.5 and push-1N).
Each (goal, method) trial plans in its own process (and executes the plan in simulation with --simulate);
finished trials are written atomically under OUT/trials/, so a killed sweep rerun with the same command skips
them. Trials run on local worker processes (--workers) or on a Dask cluster
(--scheduler tcp://HOST:8786, needs the `distributed` extra and trajectotree installed on
the workers). Then: trajectotree report OUT.
"""

from __future__ import annotations

import math

from trajectotree.cli.common import (
    add_config_options,
    check_executable_hand,
    check_graspable,
    check_output_dir,
    config_from_args,
    print_json,
)
from trajectotree.config import CONTROLLERS, ConfigError, check_controller
from trajectotree.config.executor import executor_of
from trajectotree.experiments.conditions import (
    CONDITIONS,
    DEFAULT_SPEC,
    SPACE_CONDITIONS,
    SPACE_SPEC,
    check_condition,
)
from trajectotree.experiments.executions import run_executions
from trajectotree.experiments.sweep import AXIS_ALIGNED_GOALS, METHODS, SweepSpec, run_sweep

DEFAULT_GOALS = 60  # the paper's


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep", help="run the paper's experiment (random goals x methods), resumable", description=__doc__
    )
    p.add_argument(
        "--goals",
        type=int,
        help=f"number of goal rotations (default: {DEFAULT_GOALS}, as in the paper; with --axis-aligned the first "
        f"GOALS of them, default all {AXIS_ALIGNED_GOALS})",
    )
    p.add_argument(
        "--axis-aligned",
        action="store_true",
        help=f"a hand in space: the goals are the cube's {AXIS_ALIGNED_GOALS} axis-aligned orientations (the "
        "rotations taking the cube onto itself) instead of random ones",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the goal sampler (default: 0)")
    p.add_argument(
        "--max-goal",
        type=float,
        default=math.pi,
        metavar="RAD",
        help="goals are uniform in [-RAD, RAD]; in space, uniform over the orientations at most RAD from the "
        "start (default: pi, all of SO(3))",
    )
    p.add_argument(
        "--methods",
        nargs="+",
        default=list(METHODS),
        metavar="METHOD",
        help=f"planners to run (default: all; valid: {', '.join(METHODS)})",
    )
    p.add_argument("--simulate", action="store_true", help="execute every plan in simulation (tracking errors, drops)")
    p.add_argument(
        "--controllers",
        nargs="+",
        metavar="CONTROLLER",
        help=f"then execute every plan with each of these controllers (valid: {', '.join(CONTROLLERS)}) "
        "under each of --conditions; resumable, and may be added to a finished sweep",
    )
    p.add_argument(
        "--conditions",
        nargs="+",
        metavar="CONDITION",
        help=f"robustness conditions of those executions (valid: {', '.join(CONDITIONS)}; in space: "
        f"{', '.join(SPACE_CONDITIONS)}; default: nominal): see `trajectotree.experiments.conditions`",
    )
    p.add_argument(
        "--closed-loop",
        action="store_true",
        help="run those executions with the closed loop (grasp controller only: contact watch, friction "
        "and mass estimates, push reflex); the report lists them as grasp-closed-loop beside the open-loop "
        "grasp executions, so run the sweep with and without this option to compare",
    )
    p.add_argument(
        "--replan",
        action="store_true",
        help="run those executions with the closed loop replanning from the measured state when the plan no "
        "longer holds (controller.replan; implies --closed-loop); listed as grasp-replan",
    )
    p.add_argument(
        "--out",
        default="sweep",
        metavar="DIR",
        help="sweep directory (default: ./sweep); one sweep at a time (it holds DIR/.lock)",
    )
    p.add_argument(
        "--workers",
        type=int,
        metavar="K",
        help="local worker processes, one trial each at a time (default: the number of CPUs)",
    )
    p.add_argument("--scheduler", metavar="ADDRESS", help="run the trials on this Dask scheduler instead")
    p.add_argument(
        "--scheduler-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="seconds to wait for the Dask scheduler (default: 30)",
    )
    p.add_argument(
        "--time-limit",
        type=float,
        default=1800.0,
        metavar="S",
        help="wall-clock limit per trial, plan + simulation (default: 1800); "
        "a trial past it is killed and recorded as a timeout; may change between runs of a sweep",
    )
    p.add_argument(
        "--retry-errors",
        action="store_true",
        help="rerun trials recorded with an error (crash, timeout) instead of skipping them, "
        "with the --time-limit given now",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_config_options(p, formulation=True, space=True)
    p.set_defaults(run=run)


def run(args) -> int:
    from trajectotree.scene.spatial import is_space_hand

    if args.hand is not None and is_space_hand(args.hand):
        return run_space(args)
    if args.axis_aligned:
        raise ConfigError(
            "--axis-aligned: the axis-aligned orientations are goals of a hand in space (--hand fingerpro4)"
        )
    check_output_dir("--out", args.out)
    spec = SweepSpec(
        goals=DEFAULT_GOALS if args.goals is None else args.goals,
        seed=args.seed,
        methods=tuple(args.methods),
        simulate=args.simulate,
        config=config_from_args(args),
        max_goal=args.max_goal,
        time_limit_s=args.time_limit,
    )
    from trajectotree.scene.plant import build_scene

    # refused here, before any trial, if the hand cannot grasp the object or carry its weight
    scene = build_scene(spec.config.scene)
    check_graspable(scene, spec.config, args)
    conditions = [check_condition(c) for c in args.conditions or ()]
    controllers = [check_controller(c) for c in args.controllers or ()]
    if args.simulate or conditions or controllers or args.closed_loop or args.replan:
        check_executable_hand(scene, "the sweep's simulations")
    if (conditions or args.closed_loop or args.replan) and not controllers:
        controllers = [spec.config.sim.controller]
    try:  # the executors the options name, each chosen once here
        executors = [executor_of(c, closed_loop=args.closed_loop, replan=args.replan) for c in controllers]
    except ConfigError as e:
        raise (e.as_option("--controllers") if args.controllers else e) from None
    loop = " closed loop, replanning" if args.replan else " closed loop" if args.closed_loop else ""
    return sweep_then_execute(args, spec, executors, conditions, DEFAULT_SPEC, f"{' '.join(controllers)}{loop}")


def run_space(args) -> int:
    """`trajectotree sweep` with a hand in space: goal orientations x methods, planned (planning.spatial) and stored
    as the planar sweep stores its trials, each plan executed open loop with --simulate and then by the executors of
    --controllers (with --closed-loop, --replan) in the worlds of --conditions (conditions.SPACE_SPEC); every
    option is checked before any work."""
    from trajectotree.cli.space_options import box_size, build_args_scene, check_space_graspable, space_config
    from trajectotree.experiments.sweep import SpaceSweepObject

    config = space_config(args)
    conditions = [check_condition(c, SPACE_SPEC) for c in args.conditions or ()]
    executors = space_executors(args, config, bool(conditions))
    check_output_dir("--out", args.out)
    default_goals = AXIS_ALIGNED_GOALS if args.axis_aligned else DEFAULT_GOALS
    spec = SweepSpec(
        goals=default_goals if args.goals is None else args.goals,
        seed=args.seed,
        methods=tuple(args.methods),
        simulate=args.simulate,
        config=config,
        max_goal=args.max_goal,
        time_limit_s=args.time_limit,
        space=SpaceSweepObject(size=box_size(args), mass=args.mass),
        axis_aligned=args.axis_aligned,
    )
    check_space_graspable(build_args_scene(args, config), config, args)
    return sweep_then_execute(args, spec, executors, conditions, SPACE_SPEC, " ".join(e.value for e in executors))


def sweep_then_execute(args, spec: SweepSpec, executors: list, conditions: list, worlds, label: str) -> int:
    """Runs the sweep `spec`, then the pending executions of its plans by `executors` in `conditions` (of the
    condition spec `worlds`; none given: nominal), and prints what was done (`label` names the executors)."""
    summary = run_sweep_of_args(spec, args)
    ran = (
        run_executions(
            args.out,
            executors=executors,
            conditions=conditions or ["nominal"],
            spec=worlds,
            gains=spec.config.controller,
            sim=spec.config.sim,
            workers=args.workers,
            progress=not args.no_progress,
        )
        if executors
        else None
    )
    if args.json:
        print_json({**summary.__dict__, "executions_run": ran})
    else:
        print(summary.line())
        if ran is not None:
            print(
                f"executions: {ran} run ({label} x {' '.join(conditions or ['nominal'])}); "
                "the report tabulates them in executions.md"
            )
        print(f"next: trajectotree report {args.out}")
    return 0


def space_executors(args, config, conditions: bool) -> list:
    """The executors of --controllers (with --closed-loop, --replan; the config's controller when only those or
    --conditions are given), each one a plan in space has (execution.space_run.SPACE_EXECUTORS); ConfigError
    naming one it has not yet."""
    from trajectotree.execution.space_run import SPACE_EXECUTORS

    controllers = [check_controller(c) for c in args.controllers or ()]
    if (conditions or args.closed_loop or args.replan) and not controllers:
        controllers = [config.sim.controller]
    try:
        executors = [executor_of(c, closed_loop=args.closed_loop, replan=args.replan) for c in controllers]
    except ConfigError as e:
        raise (e.as_option("--controllers") if args.controllers else e) from None
    for executor in executors:
        if executor not in SPACE_EXECUTORS:
            loop = " --replan" if args.replan else " --closed-loop" if args.closed_loop else ""
            raise ConfigError(
                f"--controllers {' '.join(controllers)}{loop}: the executor {executor.value!r} does not execute "
                f"plans in space yet; valid: {', '.join(e.value for e in SPACE_EXECUTORS)}"
            )
    return executors


def run_sweep_of_args(spec, args):
    """run_sweep of `spec` with the command line's workers, scheduler, retries and progress."""
    return run_sweep(
        spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        scheduler_timeout_s=args.scheduler_timeout,
        retry_errors=args.retry_errors,
        progress=not args.no_progress,
    )
