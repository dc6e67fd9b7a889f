"""Options shared by several subcommands, and turning them into a Config."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from trajectotree.config import (
    DEFAULT_HAND,
    FORMULATIONS,
    HAND_NAMES,
    MAX_BOX_MASS,
    MAX_MU,
    MAX_NODES,
    MAX_OBJECT_SIZE,
    MIN_BOX_MASS,
    Config,
    ConfigError,
    ObjectConfig,
    apply_config_text,
    check_integer,
    clipped_repr,
    config_file_data,
    config_text_data,
    interval,
    load_config,
)
from trajectotree.io import (  # noqa: F401 (the commands' output-file check)
    HTML_SUFFIXES,
    cannot_create_in,
    check_name_lengths,
    check_output_file,
)

# One definition of --segments for the README, --help and the code (search.num_nodes = S + 1).
SEGMENTS_HELP = (
    "transition segments S between the N = S + 1 poses of the contact sequence, each with one "
    "contact switch at most (default: from the goal's distance, the paper's 9 for a goal within pi, "
    "one more per pi/12 rad beyond and per 0.01 m: search.min_segments, max_segment_rotation, "
    "max_segment_translation)"
)
GOAL_HELP = (
    "goal orientation of the object, rad in W, any number within +-20 pi (2 pi is a full turn, -3 pi one "
    "and a half the other way); the object keeps its position"
)
GOAL_POSE_HELP = (
    "goal pose of the object in W: position X Y (m) and orientation THETA (rad, as --goal), within the "
    "hand's workspace (`trajectotree scene` reports it)"
)
FORMULATION_HELP = (
    f"TrajectoTree's program (cito.formulation; valid: {', '.join(FORMULATIONS)}): keyframes solves "
    "each segment alone between the search's nodes, in parallel; joint is the paper's one program "
    "(default: keyframes)"
)
SIZE_RANGE = interval(0.0, MAX_OBJECT_SIZE, low_open=True)  # m, of a side, a radius or a semi-axis
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")  # what matplotlib writes here and browsers show


def add_scene_options(group, config_help: str = "YAML file with any Config fields", *, space: bool = False) -> None:
    """--config and the scene options on top of it (scene_overrides reads them); with `space`, --box-size takes
    W H for a planar hand or X Y Z for a hand in space (scene_overrides and cli.space_options check the count)."""
    group.add_argument("--config", metavar="FILE.yaml", help=config_help)
    group.add_argument(
        "--config-text",
        metavar="YAML",
        help="YAML with any Config fields, applied after --config's file, e.g. "
        "'{controller: {grasp: {tip_kp: 80}}}' (a field it does not name keeps its value)",
    )
    if space:
        group.add_argument(
            "--box-size",
            nargs="+",
            type=float,
            metavar="SIZE",
            help=f"the object is a box of this width and height W H (a planar hand), or X Y Z (a hand in space), m, "
            f"each in {SIZE_RANGE}",
        )
    else:
        group.add_argument(
            "--box-size",
            nargs=2,
            type=float,
            metavar=("W", "H"),
            help=f"the object is a box of this width and height, m, each in {SIZE_RANGE}",
        )
    group.add_argument(
        "--polygon",
        metavar='"X,Y X,Y ..."',
        help="the object is this convex polygon instead of the box: its vertices (x, y) in m in the "
        "object frame, in either orientation (re-centred at its centroid), e.g. "
        '"-0.07,-0.04 0.07,-0.04 0,0.08"',
    )
    group.add_argument(
        "--circle",
        type=float,
        metavar="R",
        help=f"the object is a disc of radius R m, in {SIZE_RANGE} (polygonized, 1 cm edges at most)",
    )
    group.add_argument(
        "--ellipse",
        nargs=2,
        type=float,
        metavar=("A", "B"),
        help=f"the object is an ellipse with semi-axes A along its x and B along its y, m, each in {SIZE_RANGE} "
        "(polygonized)",
    )
    group.add_argument(
        "--mass",
        type=float,
        metavar="KG",
        help=f"the object's mass, kg, in {interval(MIN_BOX_MASS, MAX_BOX_MASS)}",
    )
    group.add_argument(
        "--mu", type=float, metavar="MU", help=f"friction coefficient, in {interval(0.0, MAX_MU, low_open=True)}"
    )
    group.add_argument(
        "--hand",
        metavar="NAME|FILE",
        help=f"the hand: {', '.join(HAND_NAMES)} (default {DEFAULT_HAND}), or a hand description FILE.yaml, or a "
        "model FILE.sdf / FILE.urdf with FILE.yaml beside it naming each finger's joints and tip (docs/design.md)",
    )


def parse_polygon(text: str) -> tuple[tuple[float, float], ...]:
    """The vertices of --polygon "x1,y1 x2,y2 ..." (m); ConfigError naming a malformed vertex.
    Whether they make a convex polygon is ObjectConfig's check."""
    vertices = []
    for i, pair in enumerate(str(text).split()):
        parts = pair.split(",")
        try:
            if len(parts) != 2:
                raise ValueError
            vertices.append((float(parts[0]), float(parts[1])))
        except ValueError:
            raise ConfigError(
                f"--polygon vertex {i} {clipped_repr(pair)} is not x,y (two numbers in m, comma-separated, no "
                'space; vertices separated by spaces, e.g. "-0.07,-0.04 0.07,-0.04 0,0.08")'
            ) from None
    if not vertices:
        raise ConfigError(
            f"--polygon {clipped_repr(text)} has no vertices: give at least 3 as x,y pairs separated by spaces"
        )
    return tuple(vertices)


def scene_overrides(args: argparse.Namespace) -> dict:
    """The SceneConfig fields set by --box-size, --polygon, --circle, --ellipse, --mass and --mu.
    --box-size makes the object a box, the others a polygon, disc or ellipse; two of them: ConfigError."""
    scene = {}
    shapes = [o for o in ("polygon", "box_size", "circle", "ellipse") if getattr(args, o, None) is not None]
    if len(shapes) > 1:
        names = " and ".join("--" + o.replace("_", "-") for o in shapes)
        raise ConfigError(f"{names} {'both' if len(shapes) == 2 else 'all'} describe the object: give one of them")
    polygon, circle, ellipse = (getattr(args, o, None) for o in ("polygon", "circle", "ellipse"))
    try:
        if polygon is not None:
            scene["object"] = ObjectConfig(vertices=parse_polygon(polygon))
        elif circle is not None:
            scene["object"] = ObjectConfig(circle_radius=circle)
        elif ellipse is not None:
            scene["object"] = ObjectConfig(ellipse_semi_axes=tuple(ellipse))
    except ConfigError as e:
        raise in_option_terms(e, args) from None
    if getattr(args, "box_size", None) is not None:
        scene["box_width"], scene["box_height"] = planar_box_size(args)
        scene["object"] = ObjectConfig()
    if getattr(args, "mass", None) is not None:
        scene["box_mass"] = args.mass
    if getattr(args, "mu", None) is not None:
        scene["mu"] = args.mu
    if getattr(args, "hand", None) is not None:
        scene["hand"] = args.hand
    return scene


def count_text(count: int) -> str:
    return f"{count} value{'' if count == 1 else 's'}"


def planar_box_size(args: argparse.Namespace) -> tuple[float, float]:
    """--box-size W H; ConfigError naming another count (a command that also takes a hand in space reads any)."""
    if len(args.box_size) != 2:
        raise ConfigError(
            field="--box-size",
            value=list(args.box_size),
            problem=f"has {count_text(len(args.box_size))}; the hand {args.hand or DEFAULT_HAND!r} is planar",
            valid="W H (2, m) for a planar hand; X Y Z (3, m) for a hand in space (--hand fingerpro4)",
            label="valid",
        )
    return args.box_size[0], args.box_size[1]


def add_goal_options(parser: argparse.ArgumentParser) -> None:
    """--goal RAD and --goal-pose X Y THETA, one of them (or the goal section of --config)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--goal", type=float, metavar="RAD", help=GOAL_HELP)
    group.add_argument("--goal-pose", type=float, nargs=3, metavar=("X", "Y", "THETA"), help=GOAL_POSE_HELP)


def goal_from_args(args: argparse.Namespace, config: Config):
    """The checked goal (results.check_goal) of --goal or --goal-pose, else of the config file's
    goal section; ConfigError when none gives one."""
    from trajectotree.results import check_goal

    if getattr(args, "goal", None) is not None:
        return check_goal(args.goal, "--goal")
    if getattr(args, "goal_pose", None) is not None:
        return check_goal(tuple(args.goal_pose), "--goal-pose")
    if config.goal.theta is not None:
        return check_goal(config.goal)
    raise ConfigError(
        "no goal: give --goal RAD, --goal-pose X Y THETA, or a goal section in --config (goal: {theta: RAD})"
    )


def check_goal_workspace(scene, config: Config, goal, args: argparse.Namespace, start=None) -> None:
    """ConfigError (exit 2, before any planning) when the goal's position takes the object where
    the hand cannot carry it from `start` (a pose; None: scene.initial_pose;
    trajectotree.search.workspace), naming the option that set it."""
    from trajectotree.search.workspace import check_goal_position

    name = "--goal-pose X Y" if getattr(args, "goal_pose", None) is not None else "goal.position"
    check_goal_position(scene, config.search, goal, name, start=start)


def add_config_options(
    parser: argparse.ArgumentParser, *, segments: bool = True, formulation: bool = False, space: bool = False
) -> None:
    """The scene options (add_scene_options; `space`: the command takes a hand in space too), --segments and
    --formulation."""
    group = parser.add_argument_group("scene and planner settings (override --config)")
    add_scene_options(group, space=space)
    if segments:
        group.add_argument("--segments", type=int, metavar="S", help=SEGMENTS_HELP)
    if formulation:
        group.add_argument("--formulation", metavar="NAME", help=FORMULATION_HELP)


def config_from_args(args: argparse.Namespace) -> Config:
    """The Config from --config, then the individual options on top, then the object of the
    hand's YAML (scene.hand.with_hand_object) for what neither of them chose."""
    config = layered_config(args, Config())
    scene, search, cito = scene_overrides(args), {}, {}
    given = set(scene) | config_file_scene_fields(args)
    if getattr(args, "segments", None) is not None:
        check_integer("--segments", args.segments, 1, MAX_NODES - 1)
        search["num_nodes"] = args.segments + 1
    if getattr(args, "formulation", None) is not None:
        cito["formulation"] = args.formulation
    from trajectotree.scene.hand import with_hand_object

    try:
        return dataclasses.replace(
            config,
            scene=with_hand_object(dataclasses.replace(config.scene, **scene), given),
            search=dataclasses.replace(config.search, **search),
            cito=dataclasses.replace(config.cito, **cito),
        )
    except ConfigError as e:
        raise in_option_terms(e, args) from None


def layered_config(args: argparse.Namespace, base: Config) -> Config:
    """--config's file (else `base`), then --config-text's YAML on top, as Drake's yaml_load_typed layers."""
    config = load_config(args.config) if getattr(args, "config", None) else base
    text = getattr(args, "config_text", None)
    return config if text is None else apply_config_text(config, text)


def config_file_scene_fields(args: argparse.Namespace) -> set[str]:
    """The scene fields --config's file and --config-text set (load_config and apply_config_text have
    checked them)."""
    fields = set()
    if getattr(args, "config", None):
        fields |= _scene_keys(config_file_data(args.config))
    if getattr(args, "config_text", None) is not None:
        fields |= _scene_keys(config_text_data(args.config_text))
    return fields


def _scene_keys(data) -> set[str]:
    scene = data.get("scene") if isinstance(data, dict) else None
    return set(scene) if isinstance(scene, dict) else set()


def check_executable_hand(scene, use: str) -> None:
    """ConfigError (exit 2, before any work) when `use` (a simulation or a playback) needs the
    execution stage, which reads the plant's hand state port as the planner's q, and the hand
    model's joints are not in its description's finger-major order; planning and the search
    take any hand."""
    if not scene.hand_state_is_finger_major:
        raise ConfigError(
            field="scene.hand",
            value=scene.config.hand,
            problem=f": {use} uses the execution stage, which needs the model's finger joints in the "
            "description's order (finger-major, each finger's from its base out); plan and search take any order",
        )


def check_graspable(scene, config: Config, args: argparse.Namespace) -> None:
    """ConfigError (exit 2, before any planning), naming the option that set the field, when the
    hand has no initial grasp of the object or cannot hold its weight; a warning on stderr when only
    plans that switch no finger can hold it (trajectotree.planning.request.check_graspable, which
    tt.plan runs too)."""
    from trajectotree.planning.request import check_graspable as check

    try:
        warning = check(scene, config)
    except ConfigError as e:
        raise in_option_terms(e, args) from None
    print_warning(warning, args)


def check_payload(scene, config: Config, args: argparse.Namespace) -> None:
    """check_graspable's weight check alone (trajectotree.planning.request.check_payload), for the
    commands that need no grasp ranked besides it."""
    from trajectotree.planning.request import check_payload as check

    try:
        warning = check(scene, config)
    except ConfigError as e:
        raise in_option_terms(e, args) from None
    print_warning(warning, args)


def print_warning(warning: ConfigError | None, args: argparse.Namespace) -> None:
    """A check's warning (not an error: the command goes on) on stderr, naming the option as an error would."""
    if warning is not None:
        print(f"trajectotree {args.command}: warning: {in_option_terms(warning, args)}", file=sys.stderr)


def plan_request_from_args(args: argparse.Namespace, scene, config: Config, goal, **request):
    """The checked PlanRequest of a command that plans (trajectotree.planning.request.check_plan_request,
    tt.plan's own checks) from the scene, config and goal its options give and `request`'s other
    arguments (method, start, segment_workers); ConfigError naming the option that set a refused
    value, before any planning; a warning on stderr as check_graspable's."""
    from trajectotree.planning.request import check_plan_request

    name = "--goal-pose X Y" if getattr(args, "goal_pose", None) is not None else "goal.position"
    try:
        checked = check_plan_request(goal=goal, config=config, scene=scene, goal_name=name, **request)
    except ConfigError as e:
        raise in_option_terms(e, args) from None
    print_warning(checked.warning, args)
    return checked


# The config fields command-line options set: field -> (the option's argparse attribute, the option
# as the user wrote it); a ConfigError about such a field names the option when the user gave it.
OPTION_FIELDS = {
    "scene.box_width x scene.box_height": ("box_size", "--box-size W H"),
    "scene.box_width": ("box_size", "--box-size W"),
    "scene.box_height": ("box_size", "--box-size H"),
    "scene.box_mass": ("mass", "--mass"),
    "scene.mu": ("mu", "--mu"),
    "scene.hand": ("hand", "--hand"),
    "scene.object.vertices": ("polygon", "--polygon"),
    "scene.object.circle_radius": ("circle", "--circle"),
    "scene.object.ellipse_semi_axes": ("ellipse", "--ellipse"),
    "cito.formulation": ("formulation", "--formulation"),
    "controller.impedance.kp": ("kp", "--kp"),
    "controller.impedance.kv": ("kv", "--kv"),
    "controller.grasp.object_kp": ("object_kp", "--object-kp"),
    "controller.grasp.object_kd": ("object_kd", "--object-kd"),
    "controller.grasp.tip_kp": ("tip_kp", "--tip-kp"),
    "controller.grasp.tip_kd": ("tip_kd", "--tip-kd"),
    "controller.rate_hz": ("rate", "--rate"),
    "controller.estimators.friction_floor": ("friction_floor", "--friction-floor"),
}


def in_option_terms(error: ConfigError, args: argparse.Namespace) -> ConfigError:
    """`error`, naming the option that set its field when the user gave that option
    ("--polygon (scene.object.vertices[2][0]) = ..." for scene.object.vertices[2][0])."""
    attribute, option = OPTION_FIELDS.get(error.field, (None, None))
    if attribute is not None and getattr(args, attribute, None) is not None:
        return error.as_option(option)
    return error


REASON_WIDTH = 100  # characters: a reason up to this long stays on its line


def _top_level_clauses(text: str) -> list[str]:
    """`text` split at its "; " outside brackets (the search's and the physics check's reasons
    join their clauses so, and nest bracketed ones)."""
    clauses, depth, start = [], 0, 0
    for k, ch in enumerate(text):
        depth += (ch in "([{") - (ch in ")]}")
        if depth == 0 and text.startswith("; ", k):
            clauses.append(text[start:k])
            start = k + 2
    return [c for c in clauses + [text[start:]] if c]


def reason_lines(reason: str, width: int = REASON_WIDTH) -> tuple[str, list[str]]:
    """(summary, details) of a failure reason: a reason of at most `width` characters is its own
    summary with no details; a longer one (a search that found nothing: 700-1,226 characters) is
    summarized by its first clause without its bracketed parts, and detailed one clause per line,
    each wrapped to `width` (continuations indented)."""
    import textwrap

    if len(reason) <= width:
        return reason, []
    clauses = _top_level_clauses(reason)
    summary, depth = "", 0
    for k, ch in enumerate(clauses[0]):  # a bracket after a space opens details; "grasp(s)" stays
        opens = ch in "([{" and (depth > 0 or k == 0 or clauses[0][k - 1] == " ")
        depth += opens
        summary += ch if depth == 0 else ""
        depth -= depth > 0 and ch in ")]}"
    summary = " ".join(summary.split())
    if len(summary) > width:
        summary = summary[: width - 3].rstrip() + "..."
    clauses = clauses[1:] if clauses[0] == summary else clauses  # said once
    details = [
        line for c in clauses for line in textwrap.wrap(c, width, subsequent_indent="  ", break_on_hyphens=False)
    ]
    return summary, details


def print_json(data) -> None:
    json.dump(data, sys.stdout, indent=2)
    sys.stdout.write("\n")


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_output_dir(option: str, path: str | Path, files: tuple[str, ...] = ()) -> Path:
    """An output folder (created later if missing): never an existing file, its nearest
    existing ancestor a folder in which files can be created (tried, not assumed), and none
    of the `files` the command writes into it an existing folder. Checked before any work
    starts (ConfigError: exit 2)."""
    check_name_lengths(option, path, files)
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(
            f"{option} {str(path)!r} is an existing file, not a folder; give a folder (it is created if missing)"
        )
    base = _nearest_existing(path.absolute())
    if not base.is_dir():
        raise ConfigError(f"{option} {str(path)!r} cannot be created: {str(base)!r} is a file, not a folder")
    why = cannot_create_in(base)
    if why:
        raise ConfigError(f"{option} {str(path)!r} cannot be written: no file can be created in {str(base)!r} ({why})")
    for name in files:
        if (path / name).is_dir():
            raise ConfigError(
                f"{option} {str(path)!r} cannot be written: {str(path / name)!r} is a folder, where the "
                f"command writes the file {name}; move it away or give another folder"
            )
    return path
