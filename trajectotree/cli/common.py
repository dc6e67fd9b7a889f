"""Options shared by several subcommands, and turning them into a Config."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys

from trajectotree.config import Config, ConfigError, check_integer, load_config


def add_config_options(parser: argparse.ArgumentParser, *, segments: bool = True) -> None:
    group = parser.add_argument_group("scene and planner settings (override --config)")
    group.add_argument("--config", metavar="FILE.yaml", help="YAML file with any Config fields")
    group.add_argument("--box-size", nargs=2, type=float, metavar=("W", "H"), help="box width and height, m")
    group.add_argument("--mass", type=float, metavar="KG", help="box mass, kg")
    group.add_argument("--mu", type=float, metavar="MU", help="friction coefficient")
    if segments:
        group.add_argument("--segments", type=int, metavar="N",
                           help="number of transition segments, N - 1 (the paper: 9, i.e. N = 10 nodes)")


def config_from_args(args: argparse.Namespace) -> Config:
    """The Config from --config, then the individual options on top."""
    config = load_config(args.config) if getattr(args, "config", None) else Config()
    scene, search = {}, {}
    if getattr(args, "box_size", None) is not None:
        scene["box_width"], scene["box_height"] = args.box_size
    if getattr(args, "mass", None) is not None:
        scene["box_mass"] = args.mass
    if getattr(args, "mu", None) is not None:
        scene["mu"] = args.mu
    if getattr(args, "segments", None) is not None:
        check_integer("--segments", args.segments, 1, 99)
        search["num_nodes"] = args.segments + 1
    return dataclasses.replace(config, scene=dataclasses.replace(config.scene, **scene),
                               search=dataclasses.replace(config.search, **search))


def check_goal(goal: float) -> float:
    """The goal rotation (rad); the paper samples goals in [-pi, pi]."""
    if not math.isfinite(goal) or abs(goal) > math.pi + 1e-9:
        raise ConfigError(f"--goal = {goal!r} is out of range; valid range: [-pi, pi] rad ([-3.1416, 3.1416])")
    return goal


def print_json(data) -> None:
    json.dump(data, sys.stdout, indent=2)
    sys.stdout.write("\n")
