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

import math
import re
from dataclasses import dataclass
from functools import cached_property
from importlib import resources

import numpy as np
from pydrake.geometry import AddContactMaterial, Convex, ProximityProperties, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable, PlanarJoint, RotationalInertia, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import SceneConfig
from trajectotree.geometry import ConvexPolygon, rotation_2d
from trajectotree.scene.kinematics import TwoLinkFinger

NUM_FINGERS = 4
JOINTS_PER_FINGER = 2
NUM_HAND_JOINTS = NUM_FINGERS * JOINTS_PER_FINGER
MODELS_DIR = resources.files("trajectotree.models")  # models/, installed as trajectotree/models (pyproject.toml)


def _sub(text: str, pattern: str, value: str) -> str:
    new, count = re.subn(pattern, value, text)
    if count == 0:
        raise RuntimeError(f"model template lost the pattern {pattern!r}")
    return new


def _set_friction(text: str, mu: float) -> str:
    text = _sub(text, r"<drake:mu_dynamic>[^<]*</drake:mu_dynamic>", f"<drake:mu_dynamic>{mu!r}</drake:mu_dynamic>")
    return _sub(text, r"<drake:mu_static>[^<]*</drake:mu_static>", f"<drake:mu_static>{mu!r}</drake:mu_static>")


def box_sdf(config: SceneConfig) -> str:
    """box.sdf with the size, mass, inertia and friction of `config` (the size of its
    `object.vertices` when they are an axis-aligned rectangle)."""
    a, b = config.shape.box_half  # (w/2, h/2): of box_width x box_height, or of the rectangle given as a polygon
    w, h, d, m = 2 * a, 2 * b, config.box_depth, config.box_mass
    ixx, iyy, izz = m * (h * h + d * d) / 12, m * (w * w + d * d) / 12, m * (w * w + h * h) / 12
    text = (MODELS_DIR / "box.sdf").read_text()
    text = _sub(text, r"<size>[^<]*</size>", f"<size>{w!r} {h!r} {d!r}</size>")
    text = _sub(text, r"<mass>[^<]*</mass>", f"<mass>{m!r}</mass>")
    text = _sub(text, r"<ixx>[^<]*</ixx>", f"<ixx>{ixx!r}</ixx>")
    text = _sub(text, r"<iyy>[^<]*</iyy>", f"<iyy>{iyy!r}</iyy>")
    text = _sub(text, r"<izz>[^<]*</izz>", f"<izz>{izz!r}</izz>")
    return _set_friction(text, config.mu)


def hand_sdf(config: SceneConfig) -> str:
    """planar_hand.sdf with the fingertip friction of `config` (Drake combines
    the two friction coefficients of a contact pair; equal values keep mu)."""
    return _set_friction((MODELS_DIR / "planar_hand.sdf").read_text(), config.mu)


# The object's colour and opacity (box.sdf's diffuse), for the polygon model too.
OBJECT_RGBA = np.array([0.20, 0.45, 0.80, 0.9])


def prism_inertia(shape: ConvexPolygon, mass: float, depth: float) -> SpatialInertia:
    """M_BBo_B of a uniform prism: `shape` (about its area centroid Bo) extruded `depth` m
    along z, symmetric about z = 0. I_zz is the plate's (shape.inertia, as the planners and
    the controller use); I_xx, I_yy and I_xy from the polygon's second moments of area."""
    v = shape.vertices
    x0, y0 = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    cross = x0 * y1 - x1 * y0
    area = cross.sum() / 2
    Sxx = np.sum(cross * (x0 * x0 + x0 * x1 + x1 * x1)) / 12 / area  # m^2, (1/A) int x^2 dA
    Syy = np.sum(cross * (y0 * y0 + y0 * y1 + y1 * y1)) / 12 / area
    Sxy = np.sum(cross * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0)) / 24 / area
    dz = depth * depth / 12
    I = RotationalInertia(mass * (Syy + dz), mass * (Sxx + dz), shape.inertia(mass), -mass * Sxy, 0.0, 0.0)
    return SpatialInertia.MakeFromCentralInertia(mass, np.zeros(3), I)


def prism_points(shape: ConvexPolygon, depth: float) -> np.ndarray:
    """(3, 2V) the prism's corners in B: the vertices at z = -depth/2 and at +depth/2."""
    v = shape.vertices
    return np.vstack([np.hstack([v, np.full((len(v), 1), z)]) for z in (-depth / 2, depth / 2)]).T


def add_polygon_object(plant: MultibodyPlant, config: SceneConfig, shape: ConvexPolygon | None = None):
    """Adds the object `shape` (default config.shape) as model instance and body "box" (the
    names every caller looks up): a convex prism of depth scene.box_depth (drake Convex from
    the corners, in memory: its visual mesh travels in Meshcat's messages), mass
    scene.box_mass, uniform density (prism_inertia), friction scene.mu on its collision
    geometry (box.sdf's proximity properties). Returns its ModelInstanceIndex."""
    shape = config.shape if shape is None else shape
    instance = plant.AddModelInstance("box")
    body = plant.AddRigidBody("box", instance, prism_inertia(shape, config.box_mass, config.box_depth))
    prism = Convex(prism_points(shape, config.box_depth), "object polygon")
    proximity = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(config.mu, config.mu), properties=proximity)
    plant.RegisterCollisionGeometry(body, RigidTransform(), prism, "collision", proximity)  # box::collision
    plant.RegisterVisualGeometry(body, RigidTransform(), prism, "visual", OBJECT_RGBA)
    return instance


def add_hand_and_box(plant: MultibodyPlant, config: SceneConfig):
    """Adds the hand (joints to W) and the object (planar joint in the x-y plane)
    to an unfinalized plant, sets gravity. Returns (hand, box) model instances. The box
    (or a polygon that is an axis-aligned rectangle) comes from box.sdf, any other polygon
    from add_polygon_object."""
    parser = Parser(plant)
    parser.package_map().Add("trajectotree", str(MODELS_DIR))
    (hand,) = parser.AddModelsFromString(hand_sdf(config), "sdf")
    if config.shape.is_box:
        (box,) = parser.AddModelsFromString(box_sdf(config), "sdf")
    else:
        box = add_polygon_object(plant, config)
    plant.AddJoint(PlanarJoint("box_planar", plant.world_frame(), plant.GetFrameByName("box", box)))
    plant.mutable_gravity_field().set_gravity_vector([0.0, -config.gravity, 0.0])
    return hand, box


@dataclass(frozen=True)
class LinkRectangle:
    """A link's collision box in the plane, in the frame J of the joint that moves the link
    (all collision geometry is centred on z = 0, so planar overlap is 3D overlap)."""

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
    masses: np.ndarray  # (2,) kg, link masses
    coms: np.ndarray  # (2,) m, link centre of mass along the link's x axis
    inertias: np.ndarray  # (2,) kg m^2, link rotational inertia about z at its COM
    link_boxes: (
        tuple  # (LinkRectangle, LinkRectangle): link 1's collision box in joint 1's frame, link 2's in joint 2's
    )


@dataclass
class Scene:
    """A finalized plant with its SceneGraph, for planning-time queries."""

    config: SceneConfig
    diagram: object
    plant: MultibodyPlant
    scene_graph: SceneGraph
    hand: object  # ModelInstanceIndex
    box: object  # ModelInstanceIndex

    @cached_property
    def hand_q_indices(self) -> np.ndarray:
        """Indices of the 8 hand joints (finger-major) in the plant's positions."""
        return np.array(
            [
                self.plant.GetJointByName(f"finger{i}_joint{j}", self.hand).position_start()
                for i in range(NUM_FINGERS)
                for j in (1, 2)
            ]
        )

    @cached_property
    def hand_v_indices(self) -> np.ndarray:
        return np.array(
            [
                self.plant.GetJointByName(f"finger{i}_joint{j}", self.hand).velocity_start()
                for i in range(NUM_FINGERS)
                for j in (1, 2)
            ]
        )

    @cached_property
    def box_q_indices(self) -> np.ndarray:
        joint = self.plant.GetJointByName("box_planar")
        return np.arange(joint.position_start(), joint.position_start() + 3)

    def tip_frame(self, i: int):
        return self.plant.GetFrameByName(f"finger{i}_tip", self.hand)

    @cached_property
    def tip_radius(self) -> float:
        inspector = self.scene_graph.model_inspector()
        body = self.plant.GetBodyByName("finger0_link2", self.hand)
        for gid in self.plant.GetCollisionGeometriesForBody(body):
            shape = inspector.GetShape(gid)
            if type(shape).__name__ == "Sphere":
                return float(shape.radius())
        raise RuntimeError("finger0_link2 has no sphere collision geometry")

    @cached_property
    def fingers(self) -> tuple[FingerGeometry, ...]:
        return tuple(self._read_finger(i) for i in range(NUM_FINGERS))

    def _read_finger(self, i: int) -> FingerGeometry:
        plant, ctx = self.plant, self.plant.CreateDefaultContext()
        plant.SetPositions(ctx, self.hand, np.zeros(NUM_HAND_JOINTS))
        joints = [plant.GetJointByName(f"finger{i}_joint{j}", self.hand) for j in (1, 2)]
        links = [plant.GetBodyByName(f"finger{i}_link{j}", self.hand) for j in (1, 2)]
        X_W1 = joints[0].frame_on_child().CalcPoseInWorld(ctx)
        X_W2 = joints[1].frame_on_child().CalcPoseInWorld(ctx)
        p_WF = self.tip_frame(i).CalcPoseInWorld(ctx).translation()
        x_axis = X_W1.rotation().matrix()[:2, 0]
        inertia = [b.default_spatial_inertia() for b in links]
        return FingerGeometry(
            p_W_base=X_W1.translation()[:2].copy(),
            psi=float(np.arctan2(x_axis[1], x_axis[0])),
            l1=float(np.linalg.norm(X_W2.translation() - X_W1.translation())),
            l2=float(np.linalg.norm(p_WF - X_W2.translation())),
            q_lower=np.array([j.position_lower_limits()[0] for j in joints]),
            q_upper=np.array([j.position_upper_limits()[0] for j in joints]),
            tau_max=np.array([plant.get_joint_actuator(a).effort_limit() for a in self._actuators(i)]),
            masses=np.array([s.get_mass() for s in inertia]),
            coms=np.array([s.get_com()[0] for s in inertia]),
            inertias=np.array([s.Shift(s.get_com()).CalcRotationalInertia()[2, 2] for s in inertia]),
            link_boxes=tuple(self._read_link_rectangle(ctx, joint, body) for joint, body in zip(joints, links)),
        )

    def _read_link_rectangle(self, ctx, joint, body) -> LinkRectangle:
        """The link's box collision geometry from SceneGraph, in the frame of `joint` (which moves it)."""
        inspector = self.scene_graph.model_inspector()
        boxes = [
            g for g in self.plant.GetCollisionGeometriesForBody(body) if type(inspector.GetShape(g)).__name__ == "Box"
        ]
        if len(boxes) != 1:
            raise RuntimeError(f"{body.name()} must have exactly one box collision geometry, has {len(boxes)}")
        shape = inspector.GetShape(boxes[0])
        X_WG = body.EvalPoseInWorld(ctx) @ inspector.GetPoseInFrame(boxes[0])
        X_JG = joint.frame_on_child().CalcPoseInWorld(ctx).inverse() @ X_WG
        R_JG = X_JG.rotation().matrix()
        return LinkRectangle(
            p_JG=X_JG.translation()[:2].copy(),
            angle_JG=math.atan2(R_JG[1, 0], R_JG[0, 0]),
            half_length=shape.width() / 2,
            half_width=shape.depth() / 2,
        )

    def _actuators(self, i: int):
        names = {f"finger{i}_joint1": 0, f"finger{i}_joint2": 1}
        found = [None, None]
        for a in self.plant.GetJointActuatorIndices(self.hand):
            joint_name = self.plant.get_joint_actuator(a).joint().name()
            if joint_name in names:
                found[names[joint_name]] = a
        return found

    def positions(self, object_pose, q) -> np.ndarray:
        """The plant's position vector for an object pose (x, y, theta) and 8 joint angles."""
        positions = np.zeros(self.plant.num_positions())
        positions[self.box_q_indices] = object_pose
        positions[self.hand_q_indices] = q
        return positions

    def fingertip_positions(self, q, context=None) -> np.ndarray:
        """p_WF of the 4 fingertip centres (4, 2), from the plant."""
        context = context or self.plant.CreateDefaultContext()
        self.plant.SetPositions(context, self.positions(self.config.initial_pose, q))
        return np.array([self.tip_frame(i).CalcPoseInWorld(context).translation()[:2] for i in range(NUM_FINGERS)])

    def fingertip_jacobians(self, q, context=None) -> np.ndarray:
        """J_WF (4, 2, 8): d p_WF_i / d q_hand, from the plant."""
        plant = self.plant
        context = context or plant.CreateDefaultContext()
        plant.SetPositions(context, self.positions(self.config.initial_pose, q))
        out = np.zeros((NUM_FINGERS, 2, NUM_HAND_JOINTS))
        for i in range(NUM_FINGERS):
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
    hand, box = add_hand_and_box(plant, config)
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
