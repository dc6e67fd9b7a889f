"""The scene options of a hand in space on the command line (`scene`, `search`, `plan` and `demo` with --hand
fingerpro4 or a description of kind: space): --box-size X Y Z (m), --mass and --mu reach the scene; every option
only a planar hand uses is refused by name (exit 2), never ignored; and a box the hand has no initial grasp of
is refused before any planning (check_space_graspable)."""

from __future__ import annotations

import argparse
import dataclasses

from trajectotree.cli.common import count_text, in_option_terms, layered_config
from trajectotree.config import MAX_OBJECT_SIZE, Config, ConfigError, check_range

# The planar options each command takes that a hand in space has no use for (argparse dests): the object's
# shape in the plane, the planar path's segment count (in space the segments follow from the angle:
# search.space_tree.SPACE_MAX_SEGMENT_ROTATION) and the planar scene's figure and rotation sweep.
PLANAR_SHAPES = ("polygon", "circle", "ellipse")
PLANAR_ONLY = {
    "scene": (*PLANAR_SHAPES, "figure", "rotations"),
    "search": (*PLANAR_SHAPES, "segments"),
    "plan": (*PLANAR_SHAPES, "segments"),
    "demo": (*PLANAR_SHAPES, "segments"),
    "sweep": (*PLANAR_SHAPES, "segments", "formulation"),
}
# What a hand in space plans with (cito.spatial: one program per segment); --formulation naming it is no ignored option.
SPACE_FORMULATION = "keyframes"
# What `plan` with a hand in space takes as --formulation (cito.formulation): the keyframes programs or the joint one.
SPACE_PLAN_FORMULATIONS = (SPACE_FORMULATION, "joint")
# m per side, the cubes fingerpro4 has an initial grasp of (check_space_graspable's check), measured by
# scripts/space_box_sizes.py: every cube from 5 to 300 mm in 1 mm steps, 94 g, the default friction: one range,
# 25-280 mm (the check took 0.24 s median, 2.5 s at most, on the loaded 2 cores).
FINGERPRO4_CUBES_M = (0.025, 0.28)
SPACE_SIZE_COUNT = 3  # --box-size X Y Z for a hand in space, W H (2) for a planar one


def option_name(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _given(args: argparse.Namespace, dest: str) -> bool:
    value = getattr(args, dest, None)
    return value is not None and value is not False


def refuse_planar_options(args: argparse.Namespace) -> None:
    """ConfigError naming the first option given that only a planar hand uses (PLANAR_ONLY[args.command])."""
    for dest in PLANAR_ONLY[args.command]:
        if not _given(args, dest) or (dest == "formulation" and args.formulation == SPACE_FORMULATION):
            continue
        value = getattr(args, dest)
        raise ConfigError(
            field=option_name(dest),
            value=value,
            shown="given" if value is True else None,
            problem=f"is a planar hand's option; the hand {args.hand!r} is in space",
            valid=space_help(args.command),
            label="a hand in space takes",
        )


def space_help(command: str) -> str:
    """The options of `command` a hand in space takes, as refusals list them."""
    scene = "--box-size X Y Z, --mass KG, --mu MU, --config, --config-text"
    return {
        "scene": f"{scene}, --json",
        "search": f"--goal-quat W X Y Z or --goal-rpy R P Y, {scene}, --figure, --json",
        "plan": f"--goal-quat W X Y Z or --goal-rpy R P Y, {scene}, --method, --start, --segment-workers, "
        f"--formulation {' or '.join(SPACE_PLAN_FORMULATIONS)}, --out, --json, --html",
        "demo": f"--goal-quat W X Y Z or --goal-rpy R P Y, {scene}, "
        f"--formulation {' or '.join(SPACE_PLAN_FORMULATIONS)}, --out, --meshcat, --json",
        "sweep": f"--goals, --seed, --max-goal, --axis-aligned, --methods, {scene}, --formulation {SPACE_FORMULATION}, "
        "--simulate, --controllers, --conditions, --closed-loop, --out, --workers, --scheduler, --time-limit, "
        "--retry-errors, --json",
    }[command]


def box_size(args: argparse.Namespace) -> tuple[float, float, float] | None:
    """--box-size X Y Z (m, each in SIZE_RANGE), or None when not given; ConfigError naming another count."""
    size = getattr(args, "box_size", None)
    if size is None:
        return None
    if len(size) != SPACE_SIZE_COUNT:
        raise ConfigError(
            field="--box-size",
            value=list(size),
            problem=f"has {count_text(len(size))}; the hand {args.hand!r} is in space",
            valid="X Y Z (3, m) for a hand in space; W H (2, m) for a planar hand",
            label="valid",
        )
    for i, s in enumerate(size):
        check_range("--box-size", s, 0.0, MAX_OBJECT_SIZE, low_open=True, index=(i,))
    return tuple(float(s) for s in size)


def space_config(args: argparse.Namespace) -> Config:
    """--config, --config-text, then --mass, --mu and --hand on top (the scene a hand in space reads), after
    refusing the planar options; ConfigError naming the option that set a refused value."""
    refuse_planar_options(args)
    config = layered_config(args, Config())
    overrides = {"hand": args.hand}
    cito = {} if getattr(args, "formulation", None) is None else {"formulation": args.formulation}
    if getattr(args, "mass", None) is not None:
        overrides["box_mass"] = args.mass
    if getattr(args, "mu", None) is not None:
        overrides["mu"] = args.mu
    try:
        return dataclasses.replace(
            config,
            scene=dataclasses.replace(config.scene, **overrides),
            cito=dataclasses.replace(config.cito, **cito),
        )
    except ConfigError as e:
        raise in_option_terms(e, args) from None


def build_args_scene(args: argparse.Namespace, config: Config):
    """The SpaceScene of the options: the hand, its box of --box-size (else the hand's own size), of --mass (else
    the hand's) and the friction --mu (else the config's)."""
    from trajectotree.scene.spatial import build_space_scene

    return build_space_scene(
        args.hand,
        mu=config.scene.mu,
        gravity=config.scene.gravity,
        size=box_size(args),
        mass=args.mass if getattr(args, "mass", None) is not None else None,
    )


def check_space_graspable(scene, config: Config, args: argparse.Namespace) -> None:
    """ConfigError (exit 2, before any planning) when the search finds no initial grasp of the box at the grasp
    point (search.space_tree.space_initial_grasp: four reachable contacts in closure at mu_plan, links clear, held
    within the motors; under a second of IK), naming the size, or the mass when a light box of that size has one."""
    from trajectotree.config import MIN_BOX_MASS, mu_plan
    from trajectotree.scene.spatial import START_POSE, build_space_scene
    from trajectotree.search.space_tree import space_initial_grasp

    mu = mu_plan(config.scene, config.search)
    if space_initial_grasp(scene, START_POSE[:4], config.search, mu).success:
        return
    size, mass = scene.object.size, scene.object.mass
    light = build_space_scene(args.hand, mu=scene.object.mu, gravity=scene.gravity, size=size, mass=MIN_BOX_MASS)
    shown = " ".join(f"{s:g}" for s in size)
    if space_initial_grasp(light, START_POSE[:4], config.search, mu).success:
        raise ConfigError(
            field="--mass" if getattr(args, "mass", None) is not None else "the hand's object mass",
            value=mass,
            problem=f"kg: no initial grasp of the {shown} m box holds it within the motors "
            f"({float(scene.tau_max.min()):g} N m)",
            valid=f"a lighter box (a {MIN_BOX_MASS:g} kg one has a grasp)",
            label="valid",
        )
    cubes = "" if args.hand != "fingerpro4" else f"; fingerpro4 grasps cubes of {interval_m(FINGERPRO4_CUBES_M)}"
    raise ConfigError(
        field="--box-size" if getattr(args, "box_size", None) is not None else "the hand's object size",
        value=list(size),
        shown=f"{shown} m",
        problem=f": the hand {args.hand!r} has no initial grasp of this box at the grasp point (no four reachable "
        f"contacts in closure at mu_plan {mu:.3g} with the links clear and the weight within the motors)",
        valid=f"a box each finger reaches{cubes}",
        label="valid",
    )


def interval_m(bounds: tuple[float, float]) -> str:
    return f"{bounds[0]:g} to {bounds[1]:g} m per side"
