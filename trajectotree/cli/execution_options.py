"""The options of `trajectotree simulate` that choose an execution and its world, read the same way for a plan
in the plane (cli.simulate_cmd) and in space (cli.space_simulate): the executor, the configuration on top of the
plan's, the simulated world (--sim-mu, --sim-mass, --push) and the closed loop's summary line."""

from __future__ import annotations

import dataclasses

from trajectotree.cli.common import OPTION_FIELDS, in_option_terms, layered_config, scene_overrides
from trajectotree.config import (
    MAX_BOX_MASS,
    MAX_MU,
    MIN_BOX_MASS,
    Config,
    ConfigError,
    check_controller,
    clipped_repr,
    with_values,
)
from trajectotree.config.executor import Executor, executor_of, parse_executor


def execution_config(args, plan_config: Config) -> Config:
    """The plan's config (or --config) with the options on top; its scene must be the plan's."""
    config = layered_config(args, plan_config)
    scene = scene_overrides(args)
    gains = {
        name: getattr(args, attribute)
        for name, (attribute, _) in OPTION_FIELDS.items()
        if name.startswith("controller.") and getattr(args, attribute, None) is not None
    }
    if args.controller is not None:
        check_controller(args.controller, "--controller")
    sim = {} if args.controller is None else {"controller": args.controller}
    try:
        config = with_values(
            dataclasses.replace(config, scene=dataclasses.replace(config.scene, **scene)),
            {**gains, **{f"sim.{k}": v for k, v in sim.items()}},
        )
    except ConfigError as e:
        raise in_option_terms(e, args) from None
    differ = [
        f"scene.{f.name} = {clipped_repr(getattr(config.scene, f.name))} (the plan's: "
        f"{clipped_repr(getattr(plan_config.scene, f.name))})"
        for f in dataclasses.fields(config.scene)
        if getattr(config.scene, f.name) != getattr(plan_config.scene, f.name)
    ]
    if differ:
        raise ConfigError("the given scene differs from the one the plan was made for: " + "; ".join(differ))
    return config


def world_conditions(args, config: Config, plan_duration_s: float, components: int = 2) -> dict:
    """run_simulation's keyword arguments for --sim-mu, --sim-mass and --push (of `components` forces: 3 for a plan
    in space), checked here so that bad values stop the command before anything is written: a push must start
    before the run ends (the plan's `plan_duration_s` and sim.settle_time), or it never acts."""
    from trajectotree.config import check_range
    from trajectotree.execution.world import Conditions, parse_push

    if args.sim_mu is not None:
        check_range("--sim-mu", args.sim_mu, 0.0, MAX_MU, low_open=True)
    if args.sim_mass is not None:
        check_range("--sim-mass", args.sim_mass, MIN_BOX_MASS, MAX_BOX_MASS)
    push = None if args.push is None else parse_push(args.push, config.sim.push_duration, components)
    run_s = plan_duration_s + config.sim.settle_time
    if push is not None and push.time_s >= run_s - 1e-9:  # the knot times' rounding: 1.2 + 0.5 s is 1.7000000000000002
        raise ConfigError(
            f"--push {args.push!r} starts at {push.time_s:g} s, when the run is over: it lasts {run_s:g} s (the "
            f"plan's {plan_duration_s:g} s and sim.settle_time {config.sim.settle_time:g} s); valid range of T: "
            f"[0, {run_s:g}) s"
        )
    Conditions(mu=args.sim_mu, mass=args.sim_mass, push=push)  # raises ConfigError naming a bad value
    return {"sim_mu": args.sim_mu, "sim_mass": args.sim_mass, "push": push}


def closed_loop_line(loop: dict, mu: float, mass: float) -> str:
    """The line that sums up sim.json's "closed_loop" `loop` of a run of a plan that assumed friction `mu` and
    the object's `mass` kg."""
    return (
        f"closed loop: friction estimate {loop['mu_estimate']:.3f} (plan {mu:g}), mass estimate "
        f"{1e3 * loop['mass_estimate']:.1f} g (plan {1e3 * mass:g}), slipping "
        + ", ".join(f"{s:.2f}" for s in loop["slipping_s"])
        + f" s per finger, reflex on {loop['reflex_s']:.2f} s"
    )


def named_executor(args) -> Executor | None:
    """The executor --executor names (None: not given); ConfigError for a name that is no executor, or
    beside the older options that name a part of one (--controller, --closed-loop, --replan)."""
    if args.executor is None:
        return None
    executor = parse_executor(args.executor, "--executor")
    shorthands = [
        option
        for option, given in (
            ("--controller", args.controller is not None),
            ("--closed-loop", args.closed_loop),
            ("--replan", args.replan),
        )
        if given
    ]
    if shorthands:
        raise ConfigError(
            f"--executor {executor.value} names the whole executor: give it without {', '.join(shorthands)}"
        )
    return executor


def chosen_executor(args, config: Config) -> Executor:
    """The one executor the options name: --executor, or the controller (--controller, else the
    config's sim.controller) with --closed-loop or --replan; ConfigError for a combination that names none."""
    named = named_executor(args)
    if named is not None:
        return named
    return executor_of(config.sim.controller, closed_loop=args.closed_loop, replan=args.replan)
