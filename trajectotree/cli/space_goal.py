"""The goal orientation of a hand in space on the command line (`search` and `plan`): --goal-quat W X Y Z
(Drake's order, normalized) or --goal-rpy R P Y (rad, Drake's RollPitchYaw), each checked in one line."""

from __future__ import annotations

import math


def add_space_goal_options(parser) -> None:
    """--goal-quat W X Y Z and --goal-rpy R P Y, one of them (a hand in space's goal orientation)."""
    space = parser.add_mutually_exclusive_group()
    space.add_argument(
        "--goal-quat",
        type=float,
        nargs=4,
        metavar=("W", "X", "Y", "Z"),
        help="a hand in space's goal orientation of the cube as a quaternion (Drake's order; normalized)",
    )
    space.add_argument(
        "--goal-rpy",
        type=float,
        nargs=3,
        metavar=("R", "P", "Y"),
        help="a hand in space's goal orientation of the cube as roll, pitch, yaw in rad (Drake's RollPitchYaw)",
    )


SPACE_GOAL_OPTIONS = ("goal_quat", "goal_rpy")
MIN_QUATERNION_NORM = 1e-6  # a quaternion shorter than this names no rotation (rounding decides its direction)
MAX_RPY = 100.0  # rad, the goal's roll, pitch and yaw at most in size, as the planar goal's many turns


def _space_goal_option(args) -> str | None:
    return next((o for o in SPACE_GOAL_OPTIONS if getattr(args, o, None) is not None), None)


def space_goal(args):
    """The unit quaternion [w, x, y, z] of --goal-quat or --goal-rpy; ConfigError naming the value when
    it has a NaN or infinity, a zero norm or an angle beyond MAX_RPY, or when neither (or a planar goal) is given."""
    import numpy as np
    from pydrake.math import RollPitchYaw

    from trajectotree.config import ConfigError, check_range

    planar = next((o for o in ("goal", "goal_pose") if getattr(args, o, None) is not None), None)
    if planar is not None:
        raise ConfigError(
            field="--" + planar.replace("_", "-"),
            value=getattr(args, planar),
            problem="is a planar goal",
            valid="--goal-quat W X Y Z or --goal-rpy R P Y for a hand in space",
            label="valid",
        )
    if args.goal_quat is not None:
        for i, v in enumerate(args.goal_quat):
            check_range("--goal-quat", v, index=(i,))
        norm = math.sqrt(sum(v * v for v in args.goal_quat))
        if norm < MIN_QUATERNION_NORM:
            raise ConfigError(
                field="--goal-quat",
                value=list(args.goal_quat),
                problem=f"has norm {norm:g}",
                valid=f"a quaternion W X Y Z of norm at least {MIN_QUATERNION_NORM:g} (it is normalized)",
                label="valid",
            )
        return np.array(args.goal_quat) / norm
    if args.goal_rpy is not None:
        for i, v in enumerate(args.goal_rpy):
            check_range("--goal-rpy", v, -MAX_RPY, MAX_RPY, index=(i,))
        return RollPitchYaw(args.goal_rpy).ToQuaternion().wxyz()
    raise ConfigError("no goal: give --goal-quat W X Y Z or --goal-rpy R P Y for a hand in space")


def refuse_space_goal_on_planar_hand(args) -> None:
    """ConfigError naming --goal-quat or --goal-rpy when given with a planar hand."""
    from trajectotree.config import ConfigError

    option = _space_goal_option(args)
    if option is not None:
        raise ConfigError(
            field="--" + option.replace("_", "-"),
            value=getattr(args, option),
            problem=f"takes a hand in space; the hand {args.hand or 'planar_hand'!r} is planar",
            valid="--hand fingerpro4 or a description of kind: space (or --goal RAD, --goal-pose X Y THETA)",
            label="valid",
        )
