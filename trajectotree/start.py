"""Where a plan begins: the object's measured pose and velocity, the hand's joint angles and,
optionally, where each finger touches the object (start.json, trajectotree.io).

A plan from a start state roots the contact search at that grasp and fixes CITO's first knot to
that state (trajectotree.planning.start checks it first). Units: m, rad, m/s, rad/s.
"""

from __future__ import annotations

import enum
import json
import math
import numbers
from dataclasses import dataclass

import numpy as np

from trajectotree.config import ConfigError


class StartProblem(enum.Enum):
    MOVING = "the object is moving"
    SPINNING = "the object is turning"
    FINGER_OFF = "a fingertip does not touch the object"
    CONTACT_MISMATCH = "a given contact is not where the fingertip is"
    NOT_IN_CLOSURE = "the grasp cannot hold the object"
    WRONG_SIZE = "the state has another number of joints or contacts than the hand"
    JOINT_LIMIT = "a joint angle is outside its limits"
    OUT_OF_BOUNDS = "the object's pose is outside the scene's bounds"


@dataclass(frozen=True)
class StartRefusal:
    """Why a start state cannot be planned from, with its numbers."""

    problem: StartProblem
    finger: int | None = None
    value: float = float("nan")  # the measured quantity (m, m/s, rad, a count or the friction the grasp needs)
    limit: float = float("nan")  # what it may be at most (WRONG_SIZE: what it must be)
    lower: float = float("nan")  # what it may be at least (JOINT_LIMIT, OUT_OF_BOUNDS)
    # what `value` is: the entry ("q", "arclengths"; an object pose's "x", "y", "theta") or the model's joint
    name: str | None = None
    index: int | None = None  # the entry of q or object_pose (JOINT_LIMIT, OUT_OF_BOUNDS)

    def to_json(self) -> dict:
        numbers = {
            k: float(v)
            for k, v in (("value", self.value), ("limit", self.limit), ("lower", self.lower))
            if math.isfinite(v)
        }
        named = {
            k: v for k, v in (("finger", self.finger), ("name", self.name), ("index", self.index)) if v is not None
        }
        return {"kind": "start", "problem": self.problem.name.lower(), **numbers, **named}

    def __str__(self) -> str:
        if self.problem is StartProblem.MOVING:
            return (
                f"start: the object moves at {self.value:.3g} m/s; a plan starts at rest (at most {self.limit:g} m/s)"
            )
        if self.problem is StartProblem.SPINNING:
            return f"start: the object turns at {self.value:.3g} rad/s; a plan starts at rest (at most {self.limit:g})"
        if self.problem is StartProblem.FINGER_OFF:
            return (
                f"start: fingertip {self.finger} is {self.value * 1e3:.2f} mm from the object's surface; every "
                f"finger must touch it (within {self.limit * 1e3:g} mm) to start a plan"
            )
        if self.problem is StartProblem.CONTACT_MISMATCH:
            return (
                f"start: finger {self.finger}'s given contact is {self.value * 1e3:.2f} mm from its fingertip's "
                f"contact point; at most {self.limit * 1e3:g} mm"
            )
        if self.problem is StartProblem.WRONG_SIZE:
            entries = "joint angles" if self.name == "q" else "contacts"
            return f"start.{self.name} has {self.value:g} entries; the hand has {self.limit:g} {entries}"
        if self.problem is StartProblem.JOINT_LIMIT:
            return (
                f"start.q[{self.index}] = {self.value:.6g} rad (finger {self.finger}, joint {self.name!r}) is outside "
                f"its limits; valid range: [{self.lower:g}, {self.limit:g}] rad"
            )
        if self.problem is StartProblem.OUT_OF_BOUNDS:
            unit = "rad" if self.name == "theta" else "m"
            return (
                f"start.object_pose[{self.index}] = {self.value:.6g} {unit} ({self.name}) is outside the scene's "
                f"bounds; valid range: [{self.lower:g}, {self.limit:g}] {unit}"
            )
        return (
            f"start: the grasp of every finger is not in frictional form closure at mu_plan "
            f"{self.limit:.3g}; it needs mu {self.value:.3g}"
        )


@dataclass(frozen=True)
class StartState:
    """A measured state to plan from; the object must be (nearly) at rest in a grasp of every finger."""

    object_pose: tuple[float, float, float]  # (x m, y m, theta rad) in W
    q: tuple[float, ...]  # (J,) rad, the hand's joint angles, finger-major (planning.start checks J against the hand)
    object_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (m/s, m/s, rad/s) in W
    # m, each finger's contact as an arclength along the object's boundary (geometry.ConvexPolygon);
    # None: derived from the fingertip positions (those touching the surface)
    arclengths: tuple[float, ...] | None = None

    def __post_init__(self):
        # each vector as a tuple of Python floats: a sim's numpy rows print and compare as plain numbers
        object.__setattr__(self, "object_pose", _vector("start.object_pose", self.object_pose, 3))
        object.__setattr__(self, "q", _vector("start.q", self.q))
        object.__setattr__(self, "object_velocity", _vector("start.object_velocity", self.object_velocity, 3))
        if self.arclengths is not None:  # one per finger: planning.start checks the count against the hand
            object.__setattr__(self, "arclengths", _vector("start.arclengths", self.arclengths))

    def to_json(self) -> dict:
        return {
            "object_pose": [float(v) for v in self.object_pose],
            "object_velocity": [float(v) for v in self.object_velocity],
            "q": [float(v) for v in self.q],
            "arclengths": None if self.arclengths is None else [float(s) for s in self.arclengths],
        }

    @staticmethod
    def from_json(data, where: str = "start.json") -> StartState:
        if not isinstance(data, dict):
            raise ConfigError(
                f"{where}: a start state is a JSON object with object_pose, q (and optionally "
                f"object_velocity, arclengths); got {type(data).__name__}"
            )
        unknown = set(data) - {"object_pose", "object_velocity", "q", "arclengths"}
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {sorted(unknown)}; valid: object_pose, object_velocity, q, arclengths"
            )
        for key in ("object_pose", "q"):
            if key not in data:
                raise ConfigError(f"{where}: missing {key!r}")
        velocity, arclengths = data.get("object_velocity"), data.get("arclengths")
        fields = dict(
            object_pose=_json_numbers(where, "object_pose", data["object_pose"]),
            q=_json_numbers(where, "q", data["q"]),
            object_velocity=(0.0, 0.0, 0.0) if velocity is None else _json_numbers(where, "object_velocity", velocity),
            arclengths=None if arclengths is None else _json_numbers(where, "arclengths", arclengths),
        )
        try:
            return StartState(**fields)
        except ConfigError as e:  # a size or a NaN: named with the file it came from
            raise ConfigError(f"{where}: {e}") from None

    @staticmethod
    def from_run(t: np.ndarray, x: np.ndarray, q: np.ndarray, time_s: float) -> StartState:
        """The state of a recorded run (sim.npz's t, x, q) at its sample nearest `time_s`, the object's
        velocity by central differences."""
        k = int(np.argmin(np.abs(np.asarray(t) - time_s)))
        lo, hi = max(k - 1, 0), min(k + 1, len(t) - 1)
        velocity = (x[hi] - x[lo]) / (t[hi] - t[lo]) if hi > lo else np.zeros(3)
        return StartState(object_pose=tuple(x[k]), q=tuple(q[k]), object_velocity=tuple(velocity))


def _is_number(v) -> bool:
    """A real number that is not a bool (JSON's true is no angle, though Python reads it as 1)."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _vector(name: str, values, size: int | None = None) -> tuple[float, ...]:
    """`values` as floats; ConfigError naming `name` unless it holds `size` (None: one or more) finite numbers."""
    count = None if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") else len(values)
    if count is None or count == 0 or (size is not None and count != size):
        wanted = "one or more" if size is None else f"{size}"
        raise ConfigError(f"{name} = {values!r} must have {wanted} numbers")
    for i, v in enumerate(values):
        if not _is_number(v) or not math.isfinite(v):
            raise ConfigError(f"{name}[{i}] = {v!r} is not a finite number")
    return tuple(float(v) for v in values)


def _json_numbers(where: str, key: str, values) -> tuple:
    """A start.json entry's list, its entries numbers (not true or false, not strings); the sizes and
    finiteness are StartState's checks."""
    if not isinstance(values, list):
        raise ConfigError(f"{where}: {key} = {values!r} must be a list of numbers")
    for i, v in enumerate(values):
        if not _is_number(v):
            raise ConfigError(f"{where}: {key}[{i}] = {json.dumps(v, default=repr)} must be a number")
    return tuple(float(v) for v in values)


# -- in space --------------------------------------------------------------------------------------
MIN_QUATERNION_NORM = 1e-6  # an orientation quaternion shorter than this names no rotation (rounding decides it)


@dataclass(frozen=True)
class SpaceStartState:
    """A measured state of a hand in space to plan from (start.json with a 7-entry object_pose): the cube at
    rest in a grasp of every finger. The quaternion is normalized; planning.start checks the rest."""

    object_pose: tuple[float, ...]  # (7,) [qw, qx, qy, qz, px, py, pz] in W (m), Drake's floating-body positions
    q: tuple[float, ...]  # (J,) rad, the hand's joint angles, finger-major
    object_velocity: tuple[float, ...] = (0.0,) * 6  # (6,) [w_W (rad/s), v_W (m/s)], as plan.npz's v
    # (F, 3) m, each finger's contact point in the cube's frame B; None: derived from the fingertips
    contacts: tuple[tuple[float, float, float], ...] | None = None

    def __post_init__(self):
        pose = _vector("start.object_pose", self.object_pose, 7)
        norm = math.sqrt(sum(v * v for v in pose[:4]))
        if norm < MIN_QUATERNION_NORM:
            raise ConfigError(
                f"start.object_pose[0:4] = {list(pose[:4])} has norm {norm:g}; valid: a quaternion qw qx qy qz "
                f"of norm at least {MIN_QUATERNION_NORM:g} (it is normalized)"
            )
        object.__setattr__(self, "object_pose", tuple(v / norm for v in pose[:4]) + pose[4:])
        object.__setattr__(self, "q", _vector("start.q", self.q))
        object.__setattr__(self, "object_velocity", _vector("start.object_velocity", self.object_velocity, 6))
        if self.contacts is not None:  # one per finger: planning.start checks the count against the hand
            if len(self.contacts) == 0:
                raise ConfigError("start.contacts = [] must have one [x, y, z] (m, in the cube's frame) per finger")
            rows = tuple(_vector(f"start.contacts[{i}]", c, 3) for i, c in enumerate(self.contacts))
            object.__setattr__(self, "contacts", rows)

    def to_json(self) -> dict:
        return {
            "object_pose": [float(v) for v in self.object_pose],
            "object_velocity": [float(v) for v in self.object_velocity],
            "q": [float(v) for v in self.q],
            "contacts": None if self.contacts is None else [[float(v) for v in c] for c in self.contacts],
        }

    @staticmethod
    def from_json(data, where: str = "start.json") -> SpaceStartState:
        if not isinstance(data, dict):
            raise ConfigError(
                f"{where}: a start state in space is a JSON object with object_pose [qw, qx, qy, qz, px, py, pz], "
                f"q (and optionally object_velocity, contacts); got {type(data).__name__}"
            )
        unknown = set(data) - {"object_pose", "object_velocity", "q", "contacts"}
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {sorted(unknown)}; valid for a hand in space: object_pose, "
                "object_velocity, q, contacts"
            )
        for key in ("object_pose", "q"):
            if key not in data:
                raise ConfigError(f"{where}: missing {key!r}")
        velocity, contacts = data.get("object_velocity"), data.get("contacts")
        if contacts is not None and not isinstance(contacts, list):
            raise ConfigError(f"{where}: contacts = {contacts!r} must be a list of [x, y, z] (m), one per finger")
        fields = dict(
            object_pose=_json_numbers(where, "object_pose", data["object_pose"]),
            q=_json_numbers(where, "q", data["q"]),
            object_velocity=(0.0,) * 6 if velocity is None else _json_numbers(where, "object_velocity", velocity),
            contacts=None
            if contacts is None
            else tuple(_json_numbers(where, f"contacts[{i}]", c) for i, c in enumerate(contacts)),
        )
        try:
            return SpaceStartState(**fields)
        except ConfigError as e:  # a size, a NaN or a zero quaternion: named with the file it came from
            raise ConfigError(f"{where}: {e}") from None
