"""A planar hand as data: `HandDescription`, read from the hand's model file (SDF or URDF) by
Drake's parser, with a small YAML that says what the model file does not.

The YAML (models/planar_hand.yaml, models/drake_planar_gripper.yaml) gives
- `model`: the model file, a path relative to the YAML, or a package:// URL (Drake's own models);
- `plane`: the model axes that become the planner's x and y, y pointing up (gravity along -y);
  z = x cross y, and every finger joint must turn about +z;
- `welds` (optional): free bodies of the model fixed to the planner's world, each by its pose in
  the model frame M (xyz m, rpy rad), as a model's own example code would weld them;
- `fingers`, in order: each finger's joints from its base out, and the frame (or body) at its
  fingertip, with `tip_xyz` (m, in that frame) when the fingertip sphere's centre is not its origin.
Everything else is read from the plant built from the model file, at zero joint angles: base
positions, link directions and lengths, joint and torque limits, link masses and inertias, the
fingertip sphere and the links' collision boxes (docs/design.md, "The hand description").

`hand_file(spec)` resolves a hand name (models/NAME.yaml), PATH.yaml, or PATH.sdf / PATH.urdf with
PATH.yaml beside it; `add_hand` adds it to an unfinalized plant (welds, plane, fingertip frames,
friction); `read_hand` reads the `HandDescription` from the finalized plant; `load_hand(spec)` does
all three on a plant of its own. A model that does not fit (a missing joint, a finger with one
joint, fewer than three fingers, a joint off the plane, a joint two fingers name or a moving joint
of the model that no finger names) raises `HandError` naming the finger, the joint and the file.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from pydrake.geometry import RoleAssign, SceneGraph
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import FixedOffsetFrame
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import (
    DEFAULT_HAND,
    HAND_NAMES,
    SPACE_HAND_NAMES,
    ConfigError,
    SceneConfig,
    clipped_repr,
    is_file,
)
from trajectotree.geometry import rotation_2d
from trajectotree.scene.kinematics import TwoLinkFinger
from trajectotree.typed_yaml import YamlError, read_yaml

MODELS_DIR = resources.files("trajectotree.models")  # models/, installed as trajectotree/models (pyproject.toml)
MODEL_SUFFIXES = (".sdf", ".urdf")
YAML_SUFFIXES = (".yaml", ".yml")
MIN_FINGERS = 3  # a switch leaves the others holding: two at least
JOINTS_PER_FINGER = 2  # fingers of more links are not supported yet
PLANE_TOLERANCE = 1e-9  # m or rad: how far a finger's joints, links and tip may lie off the plane
ADDED_TIP_FRAME = "trajectotree_tip{i}"  # the frame add_hand adds at a fingertip sphere's centre (tip_xyz given)


class HandError(ConfigError):
    """A hand description that cannot be read (CLI exit 2): names the file and what is wrong."""

    def __init__(self, source: str, problem: str):
        self.source = source
        super().__init__(f"hand {source}: {problem}")


@dataclass(frozen=True)
class Weld:
    """A free body of the model fixed to the planner's world: its frame's pose X_MF in the model frame."""

    frame: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad, roll-pitch-yaw

    def pose(self) -> RigidTransform:
        return RigidTransform(RollPitchYaw(self.rpy), np.array(self.xyz, dtype=float))


@dataclass(frozen=True)
class FingerEntry:
    """One finger as the YAML names it."""

    joints: tuple[str, ...]  # from the base out
    tip: str  # a frame (or body) of the model
    tip_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, the fingertip sphere's centre in `tip`


@dataclass(frozen=True)
class HandObject:
    """The object a hand's YAML names as its own (`object:`, e.g. the brick of Drake's gripper
    example): what planning with that hand uses unless the scene options or a config file say
    otherwise (with_hand_object). Each field None: the scene's default."""

    size: tuple[float, float] | None = None  # m, a box's width and height (SceneConfig.box_width, box_height)
    mass: float | None = None  # kg
    mu: float | None = None  # friction coefficient between fingertips and object
    inertia: float | None = None  # kg m^2, about z at the centroid (SceneConfig.object_inertia)


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

    @property
    def R_WM(self) -> np.ndarray:
        """(3, 3) the plane mapping: a vector in the model frame M to the planner's world W."""
        x, y = np.array(self.x_axis, dtype=float), np.array(self.y_axis, dtype=float)
        return np.array([x, y, np.cross(x, y)])

    def error(self, problem: str) -> HandError:
        return HandError(self.source, problem)


@dataclass(frozen=True)
class LinkRectangle:
    """A link's collision box in the plane, in the link frame L of the joint that moves the link:
    origin on the joint's axis, x along the link (towards the next joint or the fingertip), z the
    plane's normal. All collision geometry is centred on z = 0, so planar overlap is 3D overlap."""

    p_JG: np.ndarray  # (2,) m, box centre
    angle_JG: float  # rad, box x axis relative to J's x axis
    half_length: float  # m, half extent along the box x axis
    half_width: float  # m, half extent along the box y axis (in the plane)

    def corners(self, p_WJ, angle_WJ) -> np.ndarray:
        """(..., 4, 2) corners in W, counter-clockwise, when frame J is at p_WJ (..., 2) with
        angle angle_WJ (...)."""
        hl, hw = self.half_length, self.half_width
        local = np.array([[hl, -hw], [hl, hw], [-hl, hw], [-hl, -hw]]) @ rotation_2d(self.angle_JG).T + self.p_JG
        c, s = np.cos(angle_WJ)[..., None], np.sin(angle_WJ)[..., None]
        return np.asarray(p_WJ)[..., None, :] + np.stack(
            [c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]], axis=-1
        )


@dataclass(frozen=True)
class FingerGeometry(TwoLinkFinger):
    """One finger as the closed-form kinematics (`TwoLinkFinger`: p_W_base, psi, l1, l2,
    q_lower, q_upper) and dynamics see it, read from the plant."""

    tau_max: np.ndarray  # (2,) N m, torque limits
    masses: np.ndarray  # (2,) kg, link masses (with the bodies welded to them)
    coms: np.ndarray  # (2,) m, link centre of mass along the link's x axis
    inertias: np.ndarray  # (2,) kg m^2, link rotational inertia about the plane's normal at its COM
    damping: np.ndarray  # (2,) N m s/rad, the joints' viscous damping in the model
    # (LinkRectangle | None, LinkRectangle | None): link 1's collision box in joint 1's link frame, link 2's
    # in joint 2's; None for a link without collision geometry (it passes through the object in simulation too)
    link_boxes: tuple

    def gravity_gains(self, gravity: float) -> tuple[float, float]:
        """(k1, k2) N m, gravity's moments on the joints under gravity m/s^2 along -y in W:
        k1 = g (m1 c1 + m2 l1), k2 = g m2 c2, so that dV/dq = (k1 cos a1 + k2 cos a12, k2 cos a12)."""
        return gravity * (self.masses[0] * self.coms[0] + self.masses[1] * self.l1), gravity * self.masses[
            1
        ] * self.coms[1]

    def gravity_torques(self, q, gravity: float) -> np.ndarray:
        """(2,) N m, the joint torques that hold the links up at joint angles q (2,): dV/dq."""
        k1, k2 = self.gravity_gains(gravity)
        a1, a12 = self.angles(np.asarray(q, dtype=float))
        return np.array([k1 * np.cos(a1) + k2 * np.cos(a12), k2 * np.cos(a12)])


@dataclass(frozen=True)
class FingerDescription(FingerGeometry):
    """A finger of a `HandDescription`: its geometry plus the model's names for it."""

    joints: tuple[str, str]  # the model's joint names, from the base out
    link_bodies: tuple[str, str]  # the bodies they move
    tip_frame: str  # the plant frame at the fingertip sphere's centre
    tip_radius: float  # m, the fingertip sphere's radius


@dataclass(frozen=True)
class HandDescription:
    """A planar hand: its fingers in the planner's world W (x right, y up, gravity -y), read
    from its model file."""

    name: str
    source: str  # the YAML file
    model: str  # the model file (path or package:// URL)
    R_WM: np.ndarray  # (3, 3) the plane mapping: model frame M to W
    fingers: tuple[FingerDescription, ...]

    @property
    def num_fingers(self) -> int:
        return len(self.fingers)

    @property
    def num_joints(self) -> int:
        return JOINTS_PER_FINGER * len(self.fingers)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Every finger joint, finger-major (the planner's q order)."""
        return tuple(name for f in self.fingers for name in f.joints)

    @property
    def tip_radius(self) -> float:
        """m, the fingertip spheres' radius (read_hand checks that all fingers share it)."""
        return self.fingers[0].tip_radius


def finger_bodies(plant: MultibodyPlant, instance, finger: FingerDescription) -> tuple:
    """The bodies of `finger` in a plant with the hand's model: its two links and, where its tip
    frame sits on another body (Drake's gripper: a tip link welded to link 2, which carries the
    fingertip sphere), that body too, from the base out."""
    bodies = [plant.GetBodyByName(name, instance) for name in finger.link_bodies]
    tip = plant.GetFrameByName(finger.tip_frame, instance).body()
    if tip.index() not in [b.index() for b in bodies]:
        bodies.append(tip)
    return tuple(bodies)


# -- the YAML ---------------------------------------------------------------------------------
def hand_yaml_path(spec: str) -> tuple[str, Path]:
    """(name, the YAML's path) for a hand name, PATH.yaml or PATH.sdf / PATH.urdf (PATH.yaml beside it)."""
    if spec in HAND_NAMES:
        return spec, Path(str(MODELS_DIR / f"{spec}.yaml"))
    if spec in SPACE_HAND_NAMES:  # scene.spatial reads it
        raise HandError(spec, "is a hand in space (kind: space): only `trajectotree scene` takes it so far")
    path = Path(spec)
    if path.suffix.lower() in MODEL_SUFFIXES:
        beside = path.with_suffix(".yaml")
        if not is_file(beside):
            raise HandError(
                spec, f"has no description beside it: write {beside} (docs/design.md, the hand description)"
            )
        return spec, beside
    return spec, path


def _vector(source: str, where: str, value, length: int = 3) -> tuple[float, ...]:
    ok = isinstance(value, list) and len(value) == length
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok:
        raise HandError(source, f"{where} = {clipped_repr(value)} is not a list of {length} finite numbers")
    return tuple(float(v) for v in value)


def _mapping(source: str, where: str, value, keys: tuple[str, ...], required: tuple[str, ...]) -> dict:
    if not isinstance(value, dict):
        raise HandError(source, f"{where} must be a mapping with keys {list(keys)}, got {clipped_repr(value)}")
    unknown = sorted(set(value) - set(keys))
    if unknown:
        raise HandError(source, f"{where}: unknown key(s) {clipped_repr(unknown)}; valid keys: {list(keys)}")
    missing = [k for k in required if k not in value]
    if missing:
        raise HandError(source, f"{where}: missing {missing}")
    return value


def _name(source: str, where: str, value) -> str:
    if not isinstance(value, str) or not value:
        raise HandError(source, f"{where} = {clipped_repr(value)} is not a name")
    return value


def hand_file(spec: str = DEFAULT_HAND) -> HandFile:
    """The hand `spec` names (see hand_yaml_path), its YAML read and checked; HandError naming the file."""
    name, path = hand_yaml_path(spec)
    source = str(path)
    if not is_file(path):
        raise HandError(source, "does not exist")
    try:
        data = read_yaml(path)
    except YamlError as e:
        raise HandError(source, str(e)) from None
    data = _mapping(source, "the file", data, ("model", "plane", "welds", "fingers", "object"), ("fingers",))
    model = data.get("model")
    if model is None:
        if Path(spec).suffix.lower() not in MODEL_SUFFIXES:
            raise HandError(source, "names no model: give model: PATH.sdf, PATH.urdf or a package:// URL")
        model = str(Path(spec).resolve())
    elif not isinstance(model, str) or not model:
        raise HandError(source, f"model = {clipped_repr(model)} is not a file name")
    elif not model.startswith("package://"):
        model_path = (path.parent / model).resolve()
        if model_path.suffix.lower() not in MODEL_SUFFIXES:
            raise HandError(source, f"model {clipped_repr(model)} is not an SDF or URDF file")
        if not is_file(model_path):
            raise HandError(source, f"model {str(model_path)!r} does not exist")
        model = str(model_path)
    plane = _mapping(source, "plane", data.get("plane", {}), ("x_axis", "y_axis"), ())
    x_axis = _vector(source, "plane.x_axis", plane.get("x_axis", [1, 0, 0]))
    y_axis = _vector(source, "plane.y_axis", plane.get("y_axis", [0, 1, 0]))
    for axis_name, axis in (("x_axis", x_axis), ("y_axis", y_axis)):
        if abs(np.linalg.norm(axis) - 1) > 1e-12:
            raise HandError(source, f"plane.{axis_name} = {list(axis)} is not a unit vector")
    if abs(np.dot(x_axis, y_axis)) > 1e-12:
        raise HandError(source, f"plane.x_axis {list(x_axis)} and plane.y_axis {list(y_axis)} are not orthogonal")
    welds_data = data.get("welds") or []
    if not isinstance(welds_data, list):
        raise HandError(source, f"welds must be a list, got {clipped_repr(welds_data)}")
    welds = []
    for k, w in enumerate(welds_data):
        w = _mapping(source, f"welds[{k}]", w, ("frame", "xyz", "rpy"), ("frame",))
        welds.append(
            Weld(
                frame=_name(source, f"welds[{k}].frame", w["frame"]),
                xyz=_vector(source, f"welds[{k}].xyz", w.get("xyz", [0, 0, 0])),
                rpy=_vector(source, f"welds[{k}].rpy", w.get("rpy", [0, 0, 0])),
            )
        )
    fingers_data = data["fingers"]
    if not isinstance(fingers_data, list):
        raise HandError(source, f"fingers must be a list, got {clipped_repr(fingers_data)}")
    if len(fingers_data) < MIN_FINGERS:
        raise HandError(
            source,
            f"names {len(fingers_data)} finger(s); a hand needs at least {MIN_FINGERS} (a switch leaves the "
            "others holding the object)",
        )
    fingers = []
    for i, f in enumerate(fingers_data):
        f = _mapping(source, f"fingers[{i}]", f, ("joints", "tip", "tip_xyz"), ("joints", "tip"))
        joints = f["joints"]
        if not isinstance(joints, list):
            raise HandError(source, f"finger {i}: joints = {clipped_repr(joints)} is not a list of joint names")
        if len(joints) != JOINTS_PER_FINGER:
            raise HandError(
                source,
                f"finger {i} has {len(joints)} joint(s) {clipped_repr(joints)}; each finger needs "
                f"{JOINTS_PER_FINGER} revolute joints (fingers of more links are not supported yet)",
            )
        fingers.append(
            FingerEntry(
                joints=tuple(_name(source, f"finger {i}: joints[{j}]", n) for j, n in enumerate(joints)),
                tip=_name(source, f"finger {i}: tip", f["tip"]),
                tip_xyz=_vector(source, f"finger {i}: tip_xyz", f.get("tip_xyz", [0, 0, 0])),
            )
        )
    _check_joints_named_once(source, fingers)
    return HandFile(
        name=name,
        source=source,
        model=model,
        x_axis=x_axis,
        y_axis=y_axis,
        welds=tuple(welds),
        fingers=tuple(fingers),
        object=None if data.get("object") is None else _hand_object(source, data["object"]),
    )


def _check_joints_named_once(source: str, fingers: list[FingerEntry]) -> None:
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


def _hand_object(source: str, value) -> HandObject:
    """The YAML's `object` entry, checked (SceneConfig checks the values' ranges)."""
    data = _mapping(source, "object", value, ("size", "mass", "mu", "inertia"), ())

    def number(key: str) -> float | None:
        v = data.get(key)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise HandError(source, f"object.{key} = {clipped_repr(v)} is not a positive number")
        return float(v)

    size = data.get("size")
    return HandObject(
        size=None if size is None else _vector(source, "object.size", size, 2),
        mass=number("mass"),
        mu=number("mu"),
        inertia=number("inertia"),
    )


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


# -- the model in a plant -----------------------------------------------------------------------
MU_TAGS = (
    r"<drake:mu_dynamic>[^<]*</drake:mu_dynamic>",
    r"<drake:mu_static>[^<]*</drake:mu_static>",
)


def _sdf_with_friction(text: str, mu: float) -> str | None:
    """The SDF text with every collision's friction set to mu, when every <collision> carries
    Drake's two friction tags (as the project's own models do); None otherwise."""
    collisions = len(re.findall(r"<collision[\s>]", text))
    if collisions == 0 or any(len(re.findall(tag, text)) != collisions for tag in MU_TAGS):
        return None
    text = re.sub(MU_TAGS[0], f"<drake:mu_dynamic>{mu!r}</drake:mu_dynamic>", text)
    return re.sub(MU_TAGS[1], f"<drake:mu_static>{mu!r}</drake:mu_static>", text)


def _parse_model(plant: MultibodyPlant, hand: HandFile, mu: float, scene_graph: SceneGraph | None):
    """Parses the model into `plant` with fingertip-and-link friction mu (Drake combines the two
    coefficients of a contact pair; equal values keep mu). A local SDF that states its friction
    on every collision has it rewritten in its text; any other model gets it through SceneGraph's
    proximity properties, which needs `scene_graph` when the plant registers geometry."""
    parser = Parser(plant)
    parser.package_map().Add("trajectotree", str(MODELS_DIR))
    text = None
    if not hand.model.startswith("package://") and hand.model.lower().endswith(".sdf"):
        text = _sdf_with_friction(Path(hand.model).read_text(), mu)
    try:
        if text is not None:
            instances = parser.AddModelsFromString(text, "sdf")
        elif hand.model.startswith("package://"):
            instances = parser.AddModels(url=hand.model)
        else:
            instances = parser.AddModels(hand.model)
    except RuntimeError as e:
        raise hand.error(f"Drake cannot parse its model {hand.model}: {e}") from None
    if len(instances) != 1:
        raise hand.error(f"its model {hand.model} holds {len(instances)} models; give a file with one")
    (instance,) = instances
    if text is None and plant.geometry_source_is_registered():
        if scene_graph is None:
            raise ValueError(f"hand {hand.source}: pass the plant's scene_graph to set the model's friction")
        inspector = scene_graph.model_inspector()
        for b in plant.GetBodyIndices(instance):
            for g in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
                props = inspector.GetProximityProperties(g)
                props.UpdateProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
                scene_graph.AssignRole(plant.get_source_id(), g, props, RoleAssign.kReplace)
    return instance


def _joint(plant: MultibodyPlant, hand: HandFile, instance, i: int, name: str):
    if not plant.HasJointNamed(name, instance):
        joints = [plant.get_joint(j).name() for j in plant.GetJointIndices(instance)]
        raise hand.error(f"finger {i}: its model {hand.model} has no joint {name!r}; its joints: {joints}")
    joint = plant.GetJointByName(name, instance)
    if joint.type_name() != "revolute":
        raise hand.error(f"finger {i}: joint {name!r} is {joint.type_name()}; finger joints must be revolute")
    return joint


def _tip_frame(plant: MultibodyPlant, hand: HandFile, instance, i: int):
    entry = hand.fingers[i]
    if plant.HasFrameNamed(entry.tip, instance):
        frame = plant.GetFrameByName(entry.tip, instance)
    elif plant.HasBodyNamed(entry.tip, instance):
        frame = plant.GetBodyByName(entry.tip, instance).body_frame()
    else:
        raise hand.error(f"finger {i}: its model {hand.model} has no frame or body {entry.tip!r} (its tip)")
    return frame


def add_hand(plant: MultibodyPlant, hand: HandFile, mu: float, scene_graph: SceneGraph | None = None):
    """Adds hand `hand` to an unfinalized plant: its model (friction mu), its welds (X_WM X_MF),
    a frame at each fingertip sphere's centre when `tip_xyz` is given. Checks the names (joints,
    frames) and the fingers' chains. Returns the model instance."""
    instance = _parse_model(plant, hand, mu, scene_graph)
    X_WM = RigidTransform(RotationMatrix(hand.R_WM), np.zeros(3))
    for weld in hand.welds:
        if not plant.HasFrameNamed(weld.frame, instance):
            raise hand.error(f"welds: its model {hand.model} has no frame {weld.frame!r}")
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(weld.frame, instance), X_WM @ weld.pose())
    identity = np.array_equal(hand.R_WM, np.eye(3))
    for i, entry in enumerate(hand.fingers):
        j1, j2 = (_joint(plant, hand, instance, i, name) for name in entry.joints)
        if j2.parent_body().index() != j1.child_body().index():
            raise hand.error(
                f"finger {i}: joint {j2.name()!r} does not follow joint {j1.name()!r} (its parent is "
                f"{j2.parent_body().name()!r}, not {j1.child_body().name()!r})"
            )
        if j1.parent_body().index() == plant.world_body().index() and not identity:
            raise hand.error(
                f"finger {i}: joint {j1.name()!r} hangs from the world, which the plane mapping cannot turn; "
                "give the plane as x_axis [1, 0, 0], y_axis [0, 1, 0] or weld a base body instead"
            )
        frame = _tip_frame(plant, hand, instance, i)
        if any(entry.tip_xyz):
            plant.AddFrame(
                FixedOffsetFrame(
                    ADDED_TIP_FRAME.format(i=i),
                    frame,
                    RigidTransform(np.array(entry.tip_xyz, dtype=float)),
                    instance,
                )
            )
    _check_every_joint_named(plant, hand, instance)
    return instance


def _check_every_joint_named(plant: MultibodyPlant, hand: HandFile, instance) -> None:
    """HandError naming the joints of the model that move and no finger names: the planner's q, the
    controller's torques and the simulated hand state are the named joints, so a model joint left out
    would make the simulation's state larger than the plan's."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices(instance)]
    movable = [j.name() for j in joints if j.num_positions() > 0]
    named = {name for entry in hand.fingers for name in entry.joints}
    unnamed = [name for name in movable if name not in named]
    if unnamed:
        raise hand.error(
            f"no finger names joint(s) {unnamed} of its model {hand.model}; each of its moving joints must be "
            f"one finger's: {movable}"
        )


def tip_frame_name(hand: HandFile, i: int) -> str:
    """The plant frame at finger i's fingertip sphere centre (add_hand's, or the named one)."""
    entry = hand.fingers[i]
    return ADDED_TIP_FRAME.format(i=i) if any(entry.tip_xyz) else entry.tip


# -- the description from the finalized plant -------------------------------------------------------
def _unit(v: np.ndarray) -> np.ndarray:
    """v / |v|, snapped to the axis it lies along (within 1e-9) so that an axis-aligned link
    keeps exact zeros (the plant's own frames then pass through unchanged)."""
    u = v / np.linalg.norm(v)
    k = int(np.argmax(np.abs(u)))
    if np.all(np.abs(np.delete(u, k)) < 1e-9):
        u = np.zeros(3)
        u[k] = math.copysign(1.0, v[k])
    return u


def _link_frame(X_WJ: RigidTransform, axis_J: np.ndarray, d_J: np.ndarray) -> tuple[RigidTransform, RigidTransform]:
    """(X_JL, X_WL): the link frame L at joint J (x along the link d_J, z the joint axis), in J and in W."""
    R_JL = np.column_stack([d_J, np.cross(axis_J, d_J), axis_J])
    if np.array_equal(R_JL, np.eye(3)):  # the joint frame already is the link frame: keep the plant's numbers
        return RigidTransform(), X_WJ
    X_JL = RigidTransform(RotationMatrix(R_JL), np.zeros(3))
    return X_JL, X_WJ @ X_JL


def _compose(X_AB: RigidTransform, X_BC: RigidTransform) -> RigidTransform:
    """X_AB X_BC, the plant's numbers unchanged when X_BC is the identity."""
    if X_BC.IsExactlyIdentity():
        return X_AB
    return X_AB @ X_BC


def _snapped(X: RigidTransform) -> RigidTransform:
    """X with entries within 1e-12 of 0 or +-1 made exact: a frame the SDF poses by a chain of
    relative poses carries 1e-17 residues (planar_hand's joint frames sit 2.8e-17 m off their
    links' origins), which would otherwise move a link's COM by as much."""
    M = X.GetAsMatrix4()
    for exact in (0.0, 1.0, -1.0):
        M[np.abs(M - exact) < 1e-12] = exact
    return RigidTransform(M) if not np.array_equal(M, np.eye(4)) else RigidTransform()


def _link_inertia(plant: MultibodyPlant, context, body, X_BL: RigidTransform):
    """(mass, com along L's x, inertia about L's z at the COM) of `body` and the bodies welded to it."""
    welded = [b for b in plant.GetBodiesWeldedTo(body) if b.index() != body.index()]
    if welded:
        M = plant.CalcSpatialInertia(context, body.body_frame(), [body.index()] + [b.index() for b in welded])
    else:
        M = body.default_spatial_inertia()
    com_B = M.get_com()
    com_L = com_B if X_BL.IsExactlyIdentity() else X_BL.inverse() @ com_B
    I_B = M.Shift(com_B).CalcRotationalInertia().CopyToFullMatrix3()
    z_B = X_BL.rotation().matrix()[:, 2]
    return M.get_mass(), com_L, float(z_B @ I_B @ z_B) if not X_BL.IsExactlyIdentity() else float(I_B[2, 2])


def _shapes(plant: MultibodyPlant, scene_graph: SceneGraph, body):
    """[(geometry id, shape)] of the collision geometry on `body` and the bodies welded to it."""
    inspector = scene_graph.model_inspector()
    bodies = [body] + [b for b in plant.GetBodiesWeldedTo(body) if b.index() != body.index()]
    return [(g, inspector.GetShape(g)) for b in bodies for g in plant.GetCollisionGeometriesForBody(b)]


def _geometry_pose(plant: MultibodyPlant, scene_graph: SceneGraph, context, g) -> RigidTransform:
    inspector = scene_graph.model_inspector()
    body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
    return body.EvalPoseInWorld(context) @ inspector.GetPoseInFrame(g)


def _rectangle(hand: HandFile, where: str, X_WL: RigidTransform, X_WG: RigidTransform, shape) -> LinkRectangle:
    """A Box's footprint in the plane, in the link frame L."""
    X_LG = X_WL.inverse() @ X_WG
    R_LG = X_LG.rotation().matrix()
    normal = int(np.argmax(np.abs(R_LG[2])))  # the box axis along the plane's normal
    if abs(abs(R_LG[2, normal]) - 1) > PLANE_TOLERANCE or abs(X_LG.translation()[2]) > PLANE_TOLERANCE:
        raise hand.error(f"{where}: its collision box is tilted out of the plane or off it")
    a, b = (k for k in range(3) if k != normal)
    size = (shape.width(), shape.depth(), shape.height())
    return LinkRectangle(
        p_JG=X_LG.translation()[:2].copy(),
        angle_JG=math.atan2(R_LG[1, a], R_LG[0, a]),
        half_length=size[a] / 2,
        half_width=size[b] / 2,
    )


def read_hand(plant: MultibodyPlant, scene_graph: SceneGraph, instance, hand: HandFile) -> HandDescription:
    """The description of hand `hand` (added by add_hand) from the finalized plant, at zero joint angles."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, instance, np.zeros(plant.num_positions(instance)))
    actuated = {
        plant.get_joint_actuator(a).joint().index(): plant.get_joint_actuator(a).effort_limit()
        for a in plant.GetJointActuatorIndices(instance)
    }
    fixed = {b.index() for b in plant.GetBodiesWeldedTo(plant.world_body())}
    fingers = []
    for i, entry in enumerate(hand.fingers):
        joints = [plant.GetJointByName(name, instance) for name in entry.joints]
        base = joints[0].parent_body()
        if base.index() not in fixed:
            raise hand.error(
                f"finger {i}: its base {base.name()!r} (joint {joints[0].name()!r}'s parent) is free in the model; "
                "weld it (welds: frame, xyz, rpy in the model frame)"
            )
        links = [j.child_body() for j in joints]
        tip = plant.GetFrameByName(tip_frame_name(hand, i), instance)
        X_W = [j.frame_on_child().CalcPoseInWorld(context) for j in joints]
        p_WF = tip.CalcPoseInWorld(context).translation()
        ends = [X_W[1].translation(), p_WF]
        frames, directions = [], []
        for joint, X_WJ, end in zip(joints, X_W, ends):
            axis_J = np.asarray(joint.revolute_axis(), dtype=float)
            axis_W = X_WJ.rotation().matrix() @ axis_J
            if np.max(np.abs(axis_W - [0, 0, 1])) > PLANE_TOLERANCE:
                turned = "-z" if axis_W[2] < 0 else f"{np.round(axis_W, 6).tolist()}"
                raise hand.error(
                    f"finger {i}: joint {joint.name()!r} turns about {turned} of the planner's plane, not +z "
                    f"(plane.x_axis {list(hand.x_axis)}, plane.y_axis {list(hand.y_axis)})"
                )
            if abs(X_WJ.translation()[2]) > PLANE_TOLERANCE or abs(end[2]) > PLANE_TOLERANCE:
                raise hand.error(f"finger {i}: joint {joint.name()!r} or the link it moves lies off the plane z = 0")
            d_J = _unit(X_WJ.inverse() @ end)
            if abs(d_J @ axis_J) > PLANE_TOLERANCE:
                raise hand.error(f"finger {i}: the link of joint {joint.name()!r} is not perpendicular to its axis")
            X_JL, X_WL = _link_frame(X_WJ, axis_J, d_J)
            frames.append((X_JL, X_WL))
            directions.append(X_WL.rotation().matrix()[:2, 0])
        if abs(directions[0][0] * directions[1][1] - directions[0][1] * directions[1][0]) > PLANE_TOLERANCE or (
            directions[0] @ directions[1] < 0
        ):
            raise hand.error(
                f"finger {i}: at zero joint angles its fingertip is off the line of link 1 (joint "
                f"{entry.joints[1]!r} bends it); the two-link kinematics needs a straight finger at q = 0"
            )
        shapes = [_shapes(plant, scene_graph, body) for body in links]
        spheres = [
            (g, s)
            for g, s in shapes[1]
            if type(s).__name__ == "Sphere"
            and np.linalg.norm(_geometry_pose(plant, scene_graph, context, g).translation() - p_WF) < PLANE_TOLERANCE
        ]
        if len(spheres) != 1:
            offset = f" + tip_xyz {list(entry.tip_xyz)}" if any(entry.tip_xyz) else ""
            raise hand.error(
                f"finger {i}: {len(spheres)} collision spheres are centred at its tip {entry.tip!r}{offset}; "
                "it needs one (the fingertip)"
            )
        tip_sphere, radius = spheres[0][0], float(spheres[0][1].radius())
        boxes = []
        for k, link_shapes in enumerate(shapes):
            others = [(g, s) for g, s in link_shapes if g != tip_sphere]
            kinds = {type(s).__name__ for _, s in others}
            if kinds - {"Box"}:
                raise hand.error(
                    f"finger {i}: link {links[k].name()!r} has collision {sorted(kinds - {'Box'})}; "
                    "links may carry one Box (or none) besides the fingertip sphere"
                )
            if len(others) > 1:
                raise hand.error(f"finger {i}: link {links[k].name()!r} has {len(others)} collision boxes; one at most")
            boxes.append(
                _rectangle(
                    hand,
                    f"finger {i}, link {links[k].name()!r}",
                    frames[k][1],
                    _geometry_pose(plant, scene_graph, context, others[0][0]),
                    others[0][1],
                )
                if others
                else None
            )
        inertia = [
            _link_inertia(
                plant, context, body, _compose(_snapped(joint.frame_on_child().GetFixedPoseInBodyFrame()), X_JL)
            )
            for body, joint, (X_JL, _) in zip(links, joints, frames)
        ]
        for k, (_, com_L, _) in enumerate(inertia):
            if abs(com_L[1]) > PLANE_TOLERANCE or abs(com_L[2]) > PLANE_TOLERANCE:
                raise hand.error(
                    f"finger {i}: link {links[k].name()!r} has its centre of mass off the link's line "
                    f"({np.round(com_L, 6).tolist()} m in its link frame)"
                )
        for joint in joints:
            if joint.index() not in actuated:
                raise hand.error(f"finger {i}: joint {joint.name()!r} has no actuator (a zero effort limit)")
        x_axis = frames[0][1].rotation().matrix()[:2, 0]
        fingers.append(
            FingerDescription(
                p_W_base=X_W[0].translation()[:2].copy(),
                psi=float(np.arctan2(x_axis[1], x_axis[0])),
                l1=float(np.linalg.norm(X_W[1].translation() - X_W[0].translation())),
                l2=float(np.linalg.norm(p_WF - X_W[1].translation())),
                q_lower=np.array([j.position_lower_limits()[0] for j in joints]),
                q_upper=np.array([j.position_upper_limits()[0] for j in joints]),
                tau_max=np.array([actuated[j.index()] for j in joints]),
                masses=np.array([m for m, _, _ in inertia]),
                coms=np.array([com_L[0] for _, com_L, _ in inertia]),
                inertias=np.array([I for _, _, I in inertia]),
                damping=np.array([j.default_damping_vector()[0] for j in joints]),
                link_boxes=tuple(boxes),
                joints=tuple(entry.joints),
                link_bodies=tuple(b.name() for b in links),
                tip_frame=tip.name(),
                tip_radius=radius,
            )
        )
    radii = {f.tip_radius for f in fingers}
    if len(radii) > 1:
        raise hand.error(f"its fingertip spheres differ ({sorted(radii)} m); one radius for all is supported yet")
    return HandDescription(name=hand.name, source=hand.source, model=hand.model, R_WM=hand.R_WM, fingers=tuple(fingers))


def load_hand(spec: str = DEFAULT_HAND, mu: float = 0.7) -> HandDescription:
    """The description of hand `spec`, from a plant of its own (the hand alone, no gravity needed)."""
    hand = hand_file(spec)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    instance = add_hand(plant, hand, mu, scene_graph)
    plant.Finalize()
    return read_hand(plant, scene_graph, instance, hand)
