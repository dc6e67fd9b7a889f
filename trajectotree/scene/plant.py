"""The hand and the box in a Drake MultibodyPlant, built from models/ and SceneConfig.

`add_hand_and_box` adds both models to any plant (continuous for planning
queries, discrete for simulation; the object is models/box.sdf for the box, a
convex prism generated from the vertices for any other polygon). `build_scene`
makes a finalized plant with a SceneGraph for kinematic and collision queries,
and reads from it the finger geometry (`FingerGeometry`: a `kinematics.TwoLinkFinger` plus its links' masses,
inertias and torque limits) that the closed-form kinematics and dynamics use, so
the SDF stays the single source of truth for the hand.

Frames: W world (x right, y up, gravity -y), B box, F_i fingertip i (the centre
of its sphere). Plant positions are ordered [x, y, theta, q_0 ... q_7] where
q_2i, q_2i+1 are the two joints of finger i (see `Scene.hand_q_indices`).
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from pydrake.geometry import Convex, ProximityProperties, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable, PlanarJoint, RotationalInertia, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import SceneConfig
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.friction import set_friction
from trajectotree.scene.hand import (  # noqa: F401 (FingerGeometry, LinkRectangle: their old home)
    JOINTS_PER_FINGER,
    MODELS_DIR,
    FingerGeometry,
    HandDescription,
    LinkRectangle,
    add_hand,
    hand_file,
    read_hand,
)

# The default hand's finger count (tests of the default hand); every stage takes its own from scene.hand_description.
NUM_FINGERS = 4
NUM_HAND_JOINTS = NUM_FINGERS * JOINTS_PER_FINGER


def _sub(text: str, pattern: str, value: str) -> str:
    new, count = re.subn(pattern, value, text)
    if count == 0:
        raise RuntimeError(f"model template lost the pattern {pattern!r}")
    return new


def box_sdf(config: SceneConfig) -> str:
    """box.sdf with the size, mass and inertia of `config` (the size of its `object.vertices` when
    they are an axis-aligned rectangle); add_hand_and_box sets its friction (friction.set_friction)."""
    a, b = config.shape.box_half  # (w/2, h/2): of box_width x box_height, or of the rectangle given as a polygon
    w, h, d, m = 2 * a, 2 * b, config.box_depth, config.box_mass
    ixx, iyy, izz = m * (h * h + d * d) / 12, m * (w * w + d * d) / 12, m * (w * w + h * h) / 12
    if config.object_inertia is not None:
        izz = config.object_inertia
    text = (MODELS_DIR / "box.sdf").read_text()
    text = _sub(text, r"<size>[^<]*</size>", f"<size>{w!r} {h!r} {d!r}</size>")
    text = _sub(text, r"<mass>[^<]*</mass>", f"<mass>{m!r}</mass>")
    text = _sub(text, r"<ixx>[^<]*</ixx>", f"<ixx>{ixx!r}</ixx>")
    text = _sub(text, r"<iyy>[^<]*</iyy>", f"<iyy>{iyy!r}</iyy>")
    text = _sub(text, r"<izz>[^<]*</izz>", f"<izz>{izz!r}</izz>")
    return text


# The object's colour and opacity (box.sdf's diffuse), for the polygon model too.
OBJECT_RGBA = np.array([0.20, 0.45, 0.80, 0.9])


def prism_inertia(shape: ConvexPolygon, mass: float, depth: float, izz: float | None = None) -> SpatialInertia:
    """M_BBo_B of a uniform prism: `shape` (about its area centroid Bo) extruded `depth` m
    along z, symmetric about z = 0. I_zz is `izz`, else the plate's (shape.inertia, as the planners
    and the controller use); I_xx, I_yy and I_xy from the polygon's second moments of area."""
    Sxx, Syy, Sxy = shape.second_moments()
    dz = depth * depth / 12
    izz = shape.inertia(mass) if izz is None else izz
    I = RotationalInertia(mass * (Syy + dz), mass * (Sxx + dz), izz, -mass * Sxy, 0.0, 0.0)
    return SpatialInertia.MakeFromCentralInertia(mass, np.zeros(3), I)


def prism_points(shape: ConvexPolygon, depth: float) -> np.ndarray:
    """(3, 2V) the prism's corners in B: the vertices at z = -depth/2 and at +depth/2."""
    v = shape.vertices
    return np.vstack([np.hstack([v, np.full((len(v), 1), z)]) for z in (-depth / 2, depth / 2)]).T


def add_polygon_object(plant: MultibodyPlant, config: SceneConfig, shape: ConvexPolygon | None = None):
    """Adds the object `shape` (default config.shape) as model instance and body "box" (the
    names every caller looks up): a convex prism of depth scene.box_depth (drake Convex from
    the corners, in memory: its visual mesh travels in Meshcat's messages), mass
    scene.box_mass, uniform density (prism_inertia; I_zz scene.object_inertia when set); its friction
    as the box's, set by add_hand_and_box (friction.set_friction). Returns its ModelInstanceIndex."""
    shape = config.shape if shape is None else shape
    instance = plant.AddModelInstance("box")
    inertia = prism_inertia(shape, config.box_mass, config.box_depth, config.object_inertia)
    body = plant.AddRigidBody("box", instance, inertia)
    prism = Convex(prism_points(shape, config.box_depth), "object polygon")
    plant.RegisterCollisionGeometry(body, RigidTransform(), prism, "collision", ProximityProperties())  # box::collision
    plant.RegisterVisualGeometry(body, RigidTransform(), prism, "visual", OBJECT_RGBA)
    return instance


def add_hand_and_box(plant: MultibodyPlant, config: SceneConfig, scene_graph: SceneGraph | None = None):
    """Adds the hand `config.hand` (trajectotree.scene.hand: its model, welds and plane) and the
    object (planar joint in the x-y plane) to an unfinalized plant, sets gravity. Returns (hand,
    box) model instances. The box (or a polygon that is an axis-aligned rectangle) comes from
    box.sdf, any other polygon from add_polygon_object; both models' friction config.mu
    (friction.set_friction: `scene_graph`, the plant's, is needed when the plant registers geometry)."""
    hand = add_hand(plant, hand_file(config.hand), config.mu, scene_graph)
    parser = Parser(plant)
    parser.package_map().Add("trajectotree", str(MODELS_DIR))
    if config.shape.is_box:
        (box,) = parser.AddModelsFromString(box_sdf(config), "sdf")
    else:
        box = add_polygon_object(plant, config)
    set_friction(plant, scene_graph, box, config.mu)
    plant.AddJoint(PlanarJoint("box_planar", plant.world_frame(), plant.GetFrameByName("box", box)))
    plant.mutable_gravity_field().set_gravity_vector([0.0, -config.gravity, 0.0])
    return hand, box


# SceneConfig fields the planners read from the config alone, never from the plant (which serves them the hand's
# kinematics and, in the plane, a locked object joint): scenes that differ only in them can plan with one plant, so
# that a replan (a new start pose, the estimated friction and mass) waits for no plant's build (0.08-0.11 s on 2
# loaded cores).
PLANNING_FROM_CONFIG = ("initial_pose", "mu", "box_mass", "object_inertia")
# Scene's cached properties, which depend on the plant and config.hand alone
_PLANT_DERIVED = ("hand_description", "hand_q_indices", "hand_v_indices", "box_q_indices")


def plant_key(config: SceneConfig) -> SceneConfig:
    """`config` with PLANNING_FROM_CONFIG at their defaults: configs with the same key plan alike on one plant."""
    defaults = SceneConfig()
    return dataclasses.replace(config, **{name: getattr(defaults, name) for name in PLANNING_FROM_CONFIG})


@dataclass
class Scene:
    """A finalized plant with its SceneGraph, for planning-time queries."""

    config: SceneConfig
    diagram: object
    plant: MultibodyPlant
    scene_graph: SceneGraph
    hand: object  # ModelInstanceIndex
    box: object  # ModelInstanceIndex

    def for_planning(self, config: SceneConfig) -> Scene:
        """The scene the planners use for `config`, which differs from this one's config only in
        PLANNING_FROM_CONFIG (ValueError otherwise), on this scene's plant instead of a new one's: the
        planners read those values from its config. Its plant's object keeps this scene's friction and
        mass, so it is a planning scene only (a simulation builds its own plant)."""
        if plant_key(config) != plant_key(self.config):
            raise ValueError("for_planning: the configs differ in more than " + ", ".join(PLANNING_FROM_CONFIG))
        if config == self.config:
            return self
        shared = Scene(config, self.diagram, self.plant, self.scene_graph, self.hand, self.box)
        shared.__dict__.update({name: v for name, v in self.__dict__.items() if name in _PLANT_DERIVED})
        return shared

    @cached_property
    def hand_description(self) -> HandDescription:
        """The hand as data (scene.hand), read from this plant."""
        return read_hand(self.plant, self.scene_graph, self.hand, hand_file(self.config.hand))

    @property
    def num_fingers(self) -> int:
        return self.hand_description.num_fingers

    @property
    def num_hand_joints(self) -> int:
        return self.hand_description.num_joints

    @cached_property
    def hand_q_indices(self) -> np.ndarray:
        """Indices of the hand joints (finger-major, each finger's from its base out) in the plant's positions."""
        return np.array(
            [self.plant.GetJointByName(n, self.hand).position_start() for n in self.hand_description.joint_names]
        )

    @cached_property
    def hand_v_indices(self) -> np.ndarray:
        return np.array(
            [self.plant.GetJointByName(n, self.hand).velocity_start() for n in self.hand_description.joint_names]
        )

    @property
    def hand_state_is_finger_major(self) -> bool:
        """Whether the hand instance's positions and velocities are the description's joints in
        order (finger-major), as the execution stage reads the plant's hand state port."""
        return bool(np.all(np.diff(self.hand_q_indices) == 1) and np.all(np.diff(self.hand_v_indices) == 1))

    @cached_property
    def box_q_indices(self) -> np.ndarray:
        joint = self.plant.GetJointByName("box_planar")
        return np.arange(joint.position_start(), joint.position_start() + 3)

    def tip_frame(self, i: int):
        """Finger i's frame at its fingertip sphere's centre."""
        return self.plant.GetFrameByName(self.hand_description.fingers[i].tip_frame, self.hand)

    @property
    def tip_radius(self) -> float:
        return self.hand_description.tip_radius

    @property
    def fingers(self) -> tuple[FingerGeometry, ...]:
        return self.hand_description.fingers

    def positions(self, object_pose, q) -> np.ndarray:
        """The plant's position vector for an object pose (x, y, theta) and the hand's joint angles."""
        positions = np.zeros(self.plant.num_positions())
        positions[self.box_q_indices] = object_pose
        positions[self.hand_q_indices] = q
        return positions

    def fingertip_positions(self, q, context=None) -> np.ndarray:
        """p_WF of the fingertip centres (F, 2), from the plant."""
        context = context or self.plant.CreateDefaultContext()
        self.plant.SetPositions(context, self.positions(self.config.initial_pose, q))
        return np.array([self.tip_frame(i).CalcPoseInWorld(context).translation()[:2] for i in range(self.num_fingers)])

    def fingertip_jacobians(self, q, context=None) -> np.ndarray:
        """J_WF (F, 2, 2F): d p_WF_i / d q_hand, from the plant."""
        plant = self.plant
        context = context or plant.CreateDefaultContext()
        plant.SetPositions(context, self.positions(self.config.initial_pose, q))
        out = np.zeros((self.num_fingers, 2, self.num_hand_joints))
        for i in range(self.num_fingers):
            J = plant.CalcJacobianTranslationalVelocity(
                context,
                JacobianWrtVariable.kV,
                self.tip_frame(i),
                np.zeros(3),
                plant.world_frame(),
                plant.world_frame(),
            )
            out[i] = J[:2, self.hand_v_indices]
        return out


def build_scene(config: SceneConfig | None = None) -> Scene:
    """A continuous-time plant + SceneGraph with the hand and box, finalized."""
    config = config or SceneConfig()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    hand, box = add_hand_and_box(plant, config, scene_graph)
    plant.Finalize()
    diagram = builder.Build()
    return Scene(config=config, diagram=diagram, plant=plant, scene_graph=scene_graph, hand=hand, box=box)


POLYGON_NAMES = {3: "triangle", 4: "quadrilateral", 5: "pentagon", 6: "hexagon"}


def describe_object(config: SceneConfig) -> str:
    """A short name of the object for titles: "0.20 x 0.10 m box", "triangle (85 cm^2)"."""
    shape, outline = config.shape, config.object
    if shape.is_box:
        a, b = shape.box_half
        return f"{2 * a:.2f} x {2 * b:.2f} m box"
    if outline.circle_radius is not None:
        return f"disc of radius {outline.circle_radius:g} m"
    if outline.ellipse_semi_axes is not None:
        return f"ellipse of semi-axes {outline.ellipse_semi_axes[0]:g} x {outline.ellipse_semi_axes[1]:g} m"
    n = len(shape.vertices)
    return f"{POLYGON_NAMES.get(n, f'{n}-gon')} ({shape.area * 1e4:.0f} cm^2)"
