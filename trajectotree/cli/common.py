"""Options shared by several subcommands, and turning them into a Config."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

from trajectotree.config import FORMULATIONS, Config, ConfigError, check_integer, load_config

# One definition of --segments for the README, --help and the code (search.num_nodes = S + 1).
SEGMENTS_HELP = ("transition segments S between the N = S + 1 poses of the contact sequence, each with one "
                 "contact switch at most (default 9, i.e. the paper's N = 10 nodes)")
FORMULATION_HELP = (f"TrajectoTree's program (cito.formulation; valid: {', '.join(FORMULATIONS)}): keyframes solves "
                    "each segment alone between the search's nodes, in parallel; joint is the paper's one program "
                    "(default: keyframes)")
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")  # what matplotlib writes here and browsers show
HTML_SUFFIXES = (".html", ".htm")


def add_scene_options(group, config_help: str = "YAML file with any Config fields") -> None:
    """--config and the scene options on top of it (scene_overrides reads them)."""
    group.add_argument("--config", metavar="FILE.yaml", help=config_help)
    group.add_argument("--box-size", nargs=2, type=float, metavar=("W", "H"), help="box width and height, m")
    group.add_argument("--mass", type=float, metavar="KG", help="box mass, kg")
    group.add_argument("--mu", type=float, metavar="MU", help="friction coefficient")


def scene_overrides(args: argparse.Namespace) -> dict:
    """The SceneConfig fields set by --box-size, --mass and --mu."""
    scene = {}
    if getattr(args, "box_size", None) is not None:
        scene["box_width"], scene["box_height"] = args.box_size
    if getattr(args, "mass", None) is not None:
        scene["box_mass"] = args.mass
    if getattr(args, "mu", None) is not None:
        scene["mu"] = args.mu
    return scene


def add_config_options(parser: argparse.ArgumentParser, *, segments: bool = True, formulation: bool = False) -> None:
    group = parser.add_argument_group("scene and planner settings (override --config)")
    add_scene_options(group)
    if segments:
        group.add_argument("--segments", type=int, metavar="S",
                           help=SEGMENTS_HELP)
    if formulation:
        group.add_argument("--formulation", metavar="NAME", help=FORMULATION_HELP)


def config_from_args(args: argparse.Namespace) -> Config:
    """The Config from --config, then the individual options on top."""
    config = load_config(args.config) if getattr(args, "config", None) else Config()
    scene, search, cito = scene_overrides(args), {}, {}
    if getattr(args, "segments", None) is not None:
        check_integer("--segments", args.segments, 1, 99)
        search["num_nodes"] = args.segments + 1
    if getattr(args, "formulation", None) is not None:
        cito["formulation"] = args.formulation
    try:
        return dataclasses.replace(config, scene=dataclasses.replace(config.scene, **scene),
                                   search=dataclasses.replace(config.search, **search),
                                   cito=dataclasses.replace(config.cito, **cito))
    except ConfigError as e:
        raise ConfigError(in_option_terms(str(e), args)) from None


# Config fields set by command-line options, as the user wrote them (longest names first).
OPTION_NAMES = (("scene.box_width x scene.box_height", "box_size", "--box-size W H"),
                ("scene.box_width", "box_size", "--box-size W"), ("scene.box_height", "box_size", "--box-size H"),
                ("scene.box_mass", "mass", "--mass"), ("scene.mu", "mu", "--mu"),
                ("cito.formulation", "formulation", "--formulation"))


def in_option_terms(message: str, args: argparse.Namespace) -> str:
    """A config error about a field the user set with an option, named by that option."""
    for field, attribute, option in OPTION_NAMES:
        if getattr(args, attribute, None) is not None and message.startswith(field + " "):
            return f"{option} ({field}){message[len(field):]}"
    return message


def print_json(data) -> None:
    json.dump(data, sys.stdout, indent=2)
    sys.stdout.write("\n")


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_output_dir(option: str, path: str | Path) -> Path:
    """An output folder (created later if missing): never an existing file, and its nearest
    existing ancestor a writable folder. Checked before any work starts (ConfigError: exit 2)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {str(path)!r} is an existing file, not a folder; "
                         "give a folder (it is created if missing)")
    base = _nearest_existing(path.absolute())
    if not base.is_dir():
        raise ConfigError(f"{option} {str(path)!r} cannot be created: {str(base)!r} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {str(path)!r} cannot be written: no write permission in {str(base)!r}")
    return path


def check_output_file(option: str, path: str | Path, suffixes: tuple[str, ...]) -> Path:
    """An output file: its name ends in one of `suffixes`, it is not a folder, and it goes
    into an existing, writable folder. Checked before any work starts (ConfigError: exit 2)."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ConfigError(f"{option} {str(path)!r}: the file name must end in {' or '.join(suffixes)}")
    if path.is_dir():
        raise ConfigError(f"{option} {str(path)!r} is a folder; give a file name ending in {' or '.join(suffixes)}")
    folder = path.absolute().parent
    if not folder.is_dir():
        raise ConfigError(f"{option} {str(path)!r}: the folder {str(path.parent)!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {str(path)!r} cannot be written: no write permission in {str(path.parent)!r}")
    return path
