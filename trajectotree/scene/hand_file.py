"""A hand's description file (models/NAME.yaml, or PATH.yaml): its typed schema (`HandYaml`), read by
the configuration's typed loader (typed_yaml.read_yaml's guards, then Drake's yaml_load_typed through
typed_yaml.load_typed), and checked into a `HandFile` (names, unit axes, finger counts); the object a
hand names as its own (`with_hand_object`). What the model file itself says is read by
trajectotree.scene.hand_model; adding the model to a plant is trajectotree.scene.hand_plant.

The YAML (models/planar_hand.yaml, models/drake_planar_gripper.yaml) gives
- `model`: the model file, a path relative to the YAML, or a package:// URL (Drake's own models);
- `plane`: the model axes that become the planner's x and y, y pointing up (gravity along -y);
  z = x cross y, and every finger joint must turn about +z;
- `welds` (optional): free bodies of the model fixed to the planner's world, each by its pose in
  the model frame M (xyz m, rpy rad), as a model's own example code would weld them;
- `fingers`, in order: each finger's joints from its base out, and the frame (or body) at its
  fingertip, with `tip_xyz` (m, in that frame) when the fingertip sphere's centre is not its origin;
- `object` (optional): the object the hand's own example holds (HandObject).

`kind` (optional) says which: `planar` (the default, everything above) or `space` (models/fingerpro4.yaml):
a hand whose fingers move in three dimensions around a free object (trajectotree.scene.spatial). A hand in
space gives `model`, `fingers` (at least MIN_SPACE_FINGERS, each as many joints, `tip` the frame at the
fingertip sphere's centre) and `object` (`size` [x, y, z] m, `mass` kg), and no `plane` or `welds`: its
model frame is the planner's W (z up). `hand_file` reads a planar hand, `space_hand_file` one in space;
each refuses the other kind naming the commands that take it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from trajectotree.config import (
    DEFAULT_HAND,
    HAND_NAMES,
    SPACE_HAND_NAMES,
    ConfigError,
    SceneConfig,
    clipped_repr,
    is_file,
)
from trajectotree.typed_yaml import YamlError, load_typed, read_yaml

MODELS_DIR = resources.files("trajectotree.models")  # models/, installed as trajectotree/models (pyproject.toml)
MODEL_SUFFIXES = (".sdf", ".urdf")
YAML_SUFFIXES = (".yaml", ".yml")
MIN_FINGERS = 3  # a switch leaves the others holding: two at least
JOINTS_PER_FINGER = 2  # fingers of more links are not supported yet
PLANAR, SPACE = "planar", "space"  # the kinds of hand a description names (HandYaml.kind)
# three hold while one moves: two point contacts alone cannot resist a torque about the line through them
MIN_SPACE_FINGERS = 4
# the commands that take each kind of hand, for the refusal of the other kind
TAKEN_BY = {
    PLANAR: "every command",
    SPACE: "only `trajectotree scene`, `search`, `plan`, `demo`, `simulate` (open loop) and `sweep` (planning) "
    "take it so far",
}


class HandError(ConfigError):
    """A hand description that cannot be read (CLI exit 2): names the file and what is wrong."""

    def __init__(self, source: str, problem: str):
        self.source = source
        super().__init__(f"hand {source}: {problem}")


@dataclass(frozen=True)
class Weld:
    """A free body of the model fixed to the planner's world: its frame's pose X_MF in the model frame."""

    frame: str = ""
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad, roll-pitch-yaw

    def pose(self) -> RigidTransform:
        return RigidTransform(RollPitchYaw(self.rpy), np.array(self.xyz, dtype=float))


@dataclass(frozen=True)
class FingerEntry:
    """One finger as the YAML names it."""

    joints: tuple[str, ...] = ()  # from the base out
    tip: str = ""  # a frame (or body) of the model
    tip_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, the fingertip sphere's centre in `tip`


@dataclass(frozen=True)
class HandObject:
    """The object a hand's YAML names as its own (`object:`, e.g. the brick of Drake's gripper
    example): what planning with that hand uses unless the scene options or a config file say
    otherwise (with_hand_object). Each field None: the scene's default."""

    # m, a box's width and height (SceneConfig.box_width, box_height); a hand in space: its x, y and z
    size: tuple[float, ...] | None = None
    mass: float | None = None  # kg
    mu: float | None = None  # friction coefficient between fingertips and object
    inertia: float | None = None  # kg m^2, about z at the centroid (SceneConfig.object_inertia)


@dataclass(frozen=True)
class Plane:
    """The model axes that become the planner's x and y (up)."""

    x_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    y_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class HandYaml:
    """A hand description file's keys, as the typed loader reads them (unchecked: hand_file checks)."""

    model: str | None = None  # None: the PATH.sdf / PATH.urdf the YAML is beside
    plane: Plane = field(default_factory=Plane)
    welds: tuple[Weld, ...] = ()
    fingers: tuple[FingerEntry, ...] = ()
    object: HandObject | None = None
    kind: str = PLANAR  # PLANAR or SPACE


@dataclass(frozen=True)
class HandFile:
    """A hand's YAML, read and checked (not yet its model)."""

    name: str  # the hand's name (a built-in one) or the YAML's path
    source: str  # the YAML file, for messages
    model: str  # the model file: an absolute path or a package:// URL
    x_axis: tuple[float, float, float]  # the model axis that becomes the planner's x
    y_axis: tuple[float, float, float]  # ... the planner's y (up)
    welds: tuple[Weld, ...]
    fingers: tuple[FingerEntry, ...]
    object: HandObject | None = None
    kind: str = PLANAR  # PLANAR or SPACE

    @property
    def R_WM(self) -> np.ndarray:
        """(3, 3) the plane mapping: a vector in the model frame M to the planner's world W."""
        x, y = np.array(self.x_axis, dtype=float), np.array(self.y_axis, dtype=float)
        return np.array([x, y, np.cross(x, y)])

    def error(self, problem: str) -> HandError:
        return HandError(self.source, problem)


# -- the YAML ---------------------------------------------------------------------------------
def hand_yaml_path(spec: str) -> tuple[str, Path]:
    """(name, the YAML's path) for a hand name, PATH.yaml or PATH.sdf / PATH.urdf (PATH.yaml beside it)."""
    if spec in HAND_NAMES + SPACE_HAND_NAMES:
        return spec, Path(str(MODELS_DIR / f"{spec}.yaml"))
    path = Path(spec)
    if path.suffix.lower() in MODEL_SUFFIXES:
        beside = path.with_suffix(".yaml")
        if not is_file(beside):
            raise HandError(
                spec, f"has no description beside it: write {beside} (docs/design.md, the hand description)"
            )
        return spec, beside
    return spec, path


def _vector(source: str, where: str, value: tuple, length: int = 3) -> tuple[float, ...]:
    if len(value) != length or not all(math.isfinite(v) for v in value):
        raise HandError(source, f"{where} = {clipped_repr(list(value))} is not a list of {length} finite numbers")
    return value


def _name(source: str, where: str, value: str) -> str:
    if not value:
        raise HandError(source, f"{where} = {clipped_repr(value)} is not a name")
    return value


def _read(source: str, path: Path) -> HandYaml:
    """The file's HandYaml through the typed loader; HandError naming the key it refuses."""
    try:
        data = read_yaml(path)
        if not isinstance(data, dict):
            keys = [f.name for f in dataclasses.fields(HandYaml)]
            raise HandError(source, f"the file must be a mapping with keys {keys}, got {clipped_repr(data)}")
        return load_typed(HandYaml, data)
    except YamlError as e:
        raise HandError(source, str(e)) from None


def _model(source: str, spec: str, path: Path, model: str | None) -> str:
    """The model file the YAML names: an absolute path or a package:// URL."""
    if model is None:
        if Path(spec).suffix.lower() not in MODEL_SUFFIXES:
            raise HandError(source, "names no model: give model: PATH.sdf, PATH.urdf or a package:// URL")
        return str(Path(spec).resolve())
    if not model:
        raise HandError(source, f"model = {clipped_repr(model)} is not a file name")
    if model.startswith("package://"):
        return model
    model_path = (path.parent / model).resolve()
    if model_path.suffix.lower() not in MODEL_SUFFIXES:
        raise HandError(source, f"model {clipped_repr(model)} is not an SDF or URDF file")
    if not is_file(model_path):
        raise HandError(source, f"model {str(model_path)!r} does not exist")
    return str(model_path)


def _plane(source: str, plane: Plane) -> Plane:
    x_axis = _vector(source, "plane.x_axis", plane.x_axis)
    y_axis = _vector(source, "plane.y_axis", plane.y_axis)
    for axis_name, axis in (("x_axis", x_axis), ("y_axis", y_axis)):
        if abs(np.linalg.norm(axis) - 1) > 1e-12:
            raise HandError(source, f"plane.{axis_name} = {list(axis)} is not a unit vector")
    if abs(np.dot(x_axis, y_axis)) > 1e-12:
        raise HandError(source, f"plane.x_axis {list(x_axis)} and plane.y_axis {list(y_axis)} are not orthogonal")
    return plane


def _fingers(source: str, fingers: tuple[FingerEntry, ...]) -> tuple[FingerEntry, ...]:
    if len(fingers) < MIN_FINGERS:
        raise HandError(
            source,
            f"names {len(fingers)} finger(s); a hand needs at least {MIN_FINGERS} (a switch leaves the "
            "others holding the object)",
        )
    for i, f in enumerate(fingers):
        if len(f.joints) != JOINTS_PER_FINGER:
            raise HandError(
                source,
                f"finger {i} has {len(f.joints)} joint(s) {clipped_repr(list(f.joints))}; each finger needs "
                f"{JOINTS_PER_FINGER} revolute joints (fingers of more links are not supported yet)",
            )
        for j, name in enumerate(f.joints):
            _name(source, f"finger {i}: joints[{j}]", name)
        _name(source, f"finger {i}: tip", f.tip)
        _vector(source, f"finger {i}: tip_xyz", f.tip_xyz)
    _check_joints_named_once(source, fingers)
    return fingers


def _hand_object(source: str, own: HandObject | None, size_length: int = 2) -> HandObject | None:
    """The YAML's `object` entry, checked (SceneConfig checks the values' ranges): its size has
    `size_length` numbers (2 in the plane, 3 in space)."""
    if own is None:
        return None
    for key in ("mass", "mu", "inertia"):
        v = getattr(own, key)
        if v is not None and (not math.isfinite(v) or v <= 0):
            raise HandError(source, f"object.{key} = {clipped_repr(v)} is not a positive number")
    if own.size is not None:
        _vector(source, "object.size", own.size, size_length)
    return own


def _read_hand_file(spec: str) -> HandFile:
    """The hand `spec` names (see hand_yaml_path), of either kind, its YAML read and checked."""
    name, path = hand_yaml_path(spec)
    source = str(path)
    if not is_file(path):
        raise HandError(source, "does not exist")
    data = _read(source, path)
    if data.kind not in TAKEN_BY:
        raise HandError(source, f"kind = {clipped_repr(data.kind)} is not one of {list(TAKEN_BY)}")
    model = _model(source, spec, path, data.model)
    if data.kind == SPACE:
        return _space_hand(name, source, model, data)
    plane = _plane(source, data.plane)
    for k, w in enumerate(data.welds):
        _name(source, f"welds[{k}].frame", w.frame)
        _vector(source, f"welds[{k}].xyz", w.xyz)
        _vector(source, f"welds[{k}].rpy", w.rpy)
    return HandFile(
        name=name,
        source=source,
        model=model,
        x_axis=plane.x_axis,
        y_axis=plane.y_axis,
        welds=data.welds,
        fingers=_fingers(source, data.fingers),
        object=_hand_object(source, data.object),
    )


def _space_hand(name: str, source: str, model: str, data: HandYaml) -> HandFile:
    """A hand in space's HandFile: its model frame is W (no plane, no welds), each finger's tip frame
    at its fingertip sphere's centre, every finger as many joints, its object's size 3 positive numbers."""
    if data.plane != Plane() or data.welds:
        raise HandError(source, "a hand in space (kind: space) takes no plane or welds: its model frame is W, z up")
    if len(data.fingers) < MIN_SPACE_FINGERS:
        raise HandError(
            source,
            f"names {len(data.fingers)} finger(s); a hand in space needs at least {MIN_SPACE_FINGERS} (three hold "
            "while one moves)",
        )
    for i, f in enumerate(data.fingers):
        if not f.joints:
            raise HandError(source, f"finger {i} names no joints")
        for j, joint in enumerate(f.joints):
            _name(source, f"finger {i}: joints[{j}]", joint)
        _name(source, f"finger {i}: tip", f.tip)
        if any(f.tip_xyz):
            raise HandError(
                source, f"finger {i}: tip_xyz = {list(f.tip_xyz)}: a hand in space takes its tip frame at the sphere"
            )
    counts = sorted({len(f.joints) for f in data.fingers})
    if len(counts) > 1:
        raise HandError(source, f"the fingers have {counts} joints: every finger of a hand in space needs as many")
    _check_joints_named_once(source, data.fingers)
    own = _hand_object(source, data.object, size_length=3)
    if own is not None and own.size is not None and min(own.size) <= 0:
        raise HandError(source, f"object.size = {list(own.size)} is not a list of 3 positive numbers")
    return HandFile(
        name=name,
        source=source,
        model=model,
        x_axis=Plane().x_axis,
        y_axis=Plane().y_axis,
        welds=(),
        fingers=data.fingers,
        object=own,
        kind=SPACE,
    )


def _of_kind(hand: HandFile, kind: str) -> HandFile:
    """`hand` when it is of `kind`; else HandError naming the hand and the commands that take it."""
    if hand.kind == kind:
        return hand
    if hand.kind == SPACE:
        raise HandError(hand.name, f"is a hand in space (kind: space): {TAKEN_BY[SPACE]}")
    raise HandError(hand.name, "is a planar hand (kind: planar), not a hand in space (kind: space)")


def hand_file(spec: str = DEFAULT_HAND) -> HandFile:
    """The planar hand `spec` names (see hand_yaml_path), its YAML read and checked; HandError naming the
    file, or the hand when it is a hand in space."""
    return _of_kind(_read_hand_file(spec), PLANAR)


def space_hand_file(spec: str) -> HandFile:
    """The hand in space `spec` names, its YAML read and checked; HandError naming the file, or the hand
    when it is planar."""
    return _of_kind(_read_hand_file(spec), SPACE)


def hand_kind(spec: str) -> str:
    """The kind of hand `spec` names (HandYaml.kind, through the typed loader, unchecked); PLANAR for
    a file that cannot be read, whose refusal the planar reader gives."""
    try:
        _, path = hand_yaml_path(spec)
        return _read(str(path), path).kind if is_file(path) else PLANAR
    except HandError:
        return PLANAR


def _check_joints_named_once(source: str, fingers: tuple[FingerEntry, ...]) -> None:
    """HandError naming a joint that two fingers (or one twice) name: a joint moves one finger."""
    owner: dict[str, int] = {}
    for i, entry in enumerate(fingers):
        for name in entry.joints:
            if name in owner:
                who = (
                    f"finger {i} names joint {name!r} twice"
                    if owner[name] == i
                    else (f"fingers {owner[name]} and {i} both name joint {name!r}")
                )
                raise HandError(source, f"{who}; each joint of the model belongs to one finger")
            owner[name] = i


SHAPE_FIELDS = frozenset({"box_width", "box_height", "object"})  # the SceneConfig fields that say the object's shape


def with_hand_object(scene: SceneConfig, given=()) -> SceneConfig:
    """`scene` with the object of its hand's YAML (HandObject) where the user did not choose:
    `given` names the SceneConfig fields the user set (options, a config file). The size applies
    unless a shape was given (box_width, box_height, object), the mass and friction unless given,
    the inertia with the hand's own size (scaled by a given mass: the same body, denser). Unchanged
    for a hand without an object."""
    own = hand_file(scene.hand).object
    if own is None:
        return scene
    given = set(given)
    shape_given, changes = bool(given & SHAPE_FIELDS), {}
    if own.size is not None and not shape_given:
        changes["box_width"], changes["box_height"] = own.size
    if own.mass is not None and "box_mass" not in given:
        changes["box_mass"] = own.mass
    if own.mu is not None and "mu" not in given:
        changes["mu"] = own.mu
    if own.inertia is not None and not shape_given and "object_inertia" not in given:
        mass = changes.get("box_mass", scene.box_mass)
        changes["object_inertia"] = own.inertia if own.mass is None else own.inertia * mass / own.mass
    return dataclasses.replace(scene, **changes)
