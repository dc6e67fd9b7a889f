"""A hand in space and a free object in a Drake MultibodyPlant: what only space needs of the scene.

A hand in space is a YAML with `kind: space` (models/fingerpro4.yaml), read and checked by the one
typed loader of hand descriptions (trajectotree.scene.hand_file.space_hand_file): its `model` (SDF or
URDF, relative to the YAML), its `fingers` (each its joints from the base out and the frame at its
fingertip sphere's centre) and optionally its `object` (`size` [x, y, z] m, `mass` kg). The model
frame is W: z up, gravity along -z, the origin the grasp point G where the object's centre starts.
Everything else is read from the plant at zero joint angles (`kinematics.SerialFinger`: each
joint's point and axis, the fingertip centre), so the SDF stays the source of truth.

The object is a box (`box` body, uniform density) on a quaternion floating joint `box_floating`;
its positions are Drake's [qw, qx, qy, qz, px, py, pz] (W), its velocities [w_W, v_W].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import AddContactMaterial, Box, Capsule, ProximityProperties, SceneGraph, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import QuaternionFloatingJoint, SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from trajectotree.scene.hand_file import SPACE, FingerEntry, HandError, HandFile, hand_kind, space_hand_file
from trajectotree.scene.kinematics import SerialFinger

OBJECT_RGBA = np.array([0.20, 0.45, 0.80, 0.9])


def is_space_hand(spec: str) -> bool:
    """Whether `spec` names a hand in space: a built-in one, or a YAML whose kind is space."""
    return hand_kind(spec) == SPACE


@dataclass(frozen=True)
class SpaceObject:
    """The object in space: a box of `size` (x, y, z) m and `mass` kg, friction `mu` with the fingertips."""

    size: tuple[float, float, float]
    mass: float
    mu: float

    @property
    def half(self) -> np.ndarray:
        return np.array(self.size) / 2

    @property
    def inertia(self) -> np.ndarray:
        """(3, 3) kg m^2, the uniform box's rotational inertia about its centre in its own frame."""
        size = np.asarray(self.size, dtype=float)
        return self.mass * np.diag([np.sum(size**2) - s * s for s in size]) / 12


def add_space_object(plant: MultibodyPlant, box: SpaceObject):
    """Adds the box (body "box", model instance "box") on a quaternion floating joint "box_floating"
    at the grasp point, its collision geometry with friction box.mu. Returns its ModelInstanceIndex."""
    instance = plant.AddModelInstance("box")
    body = plant.AddRigidBody("box", instance, SpatialInertia(box.mass, np.zeros(3), UnitInertia.SolidBox(*box.size)))
    proximity = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(box.mu, box.mu), properties=proximity)
    plant.RegisterCollisionGeometry(body, RigidTransform(), Box(*box.size), "collision", proximity)
    plant.RegisterVisualGeometry(body, RigidTransform(), Box(*box.size), "visual", OBJECT_RGBA)
    plant.AddJoint(QuaternionFloatingJoint("box_floating", plant.world_frame(), body.body_frame()))
    return instance


@dataclass(frozen=True)
class SpaceScene:
    """A finalized continuous plant of a hand in space and its box, for planning-time queries."""

    hand_file: HandFile  # kind space
    object: SpaceObject
    gravity: float  # m/s^2, along -z
    diagram: object
    plant: MultibodyPlant
    scene_graph: SceneGraph
    hand: object  # ModelInstanceIndex
    box: object  # ModelInstanceIndex
    fingers: tuple[SerialFinger, ...]
    tip_radius: float  # m
    tau_max: np.ndarray  # (F, n) N m, each joint's motor
    hand_q_indices: np.ndarray  # (F * n,) the fingers' joints (finger-major) in the plant's positions
    box_q_indices: np.ndarray  # (7,) [qw, qx, qy, qz, px, py, pz] in the plant's positions

    @property
    def num_fingers(self) -> int:
        return len(self.fingers)

    def tip_frame(self, i: int):
        return self.plant.GetFrameByName(self.hand_file.fingers[i].tip, self.hand)

    def positions(self, box_pose, q) -> np.ndarray:
        """The plant's positions for the box's [qw, qx, qy, qz, px, py, pz] and the joint angles (F * n,)."""
        out = np.zeros(self.plant.num_positions())
        out[self.box_q_indices] = box_pose
        out[self.hand_q_indices] = np.ravel(q)
        return out

    def gravity_torques(self, q) -> np.ndarray:
        """(F, n) N m, the joint torques that hold the fingers still against their own weight at q (F, n).
        From the plant by design: a finger in space is any chain of n joints, with no closed form here
        (the planar hands' one home is scene.dynamics.HandModel.gravity_forces)."""
        context = self.plant.CreateDefaultContext()
        self.plant.SetPositions(context, self.positions(START_POSE, q))
        # CalcGravityGeneralizedForces is gravity's generalized force; the motors cancel it
        tau_g = self.plant.CalcGravityGeneralizedForces(context)
        v = [self.plant.GetJointByName(n, self.hand).velocity_start() for f in self.hand_file.fingers for n in f.joints]
        return -tau_g[v].reshape(self.num_fingers, -1)

    def link_capsules(self) -> tuple[tuple[LinkCapsule, ...], ...]:
        """Each finger's link capsules (every capsule collision geometry of its bodies), base out."""
        plant, inspector = self.plant, self.scene_graph.model_inspector()
        out = []
        for finger in self.hand_file.fingers:
            capsules = []
            for name in finger.joints:
                body = plant.GetJointByName(name, self.hand).child_body()
                for g in plant.GetCollisionGeometriesForBody(body):
                    shape = inspector.GetShape(g)
                    if isinstance(shape, Capsule):
                        X_BG = inspector.GetPoseInFrame(g)
                        half = np.array([0.0, 0.0, shape.length() / 2])  # a capsule's axis is its frame's z
                        capsules.append(LinkCapsule(body.name(), X_BG @ -half, X_BG @ half, shape.radius()))
            out.append(tuple(capsules))
        return tuple(out)

    def link_ends_W(self, poses, q) -> np.ndarray:
        """(K, F, L, 2, 3) m: the ends of each finger's link capsule axes in W with the box at `poses`
        (K, 7) and the joints at q (K, F n), from the plant's kinematics."""
        capsules = self.link_capsules()
        context = self.plant.CreateDefaultContext()
        out = np.zeros((len(q), self.num_fingers, len(capsules[0]), 2, 3))
        for k in range(len(q)):
            self.plant.SetPositions(context, self.positions(poses[k], q[k]))
            for i, finger in enumerate(capsules):
                for j, c in enumerate(finger):
                    X_WB = self.plant.GetBodyByName(c.body, self.hand).EvalPoseInWorld(context)
                    out[k, i, j] = X_WB @ c.p_B_end0, X_WB @ c.p_B_end1
        return out


@dataclass(frozen=True)
class LinkCapsule:
    """A link's collision capsule: the ends of its axis in its body's frame, and its radius."""

    body: str
    p_B_end0: np.ndarray  # (3,) m
    p_B_end1: np.ndarray  # (3,) m
    radius: float  # m


START_POSE = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # the box at the grasp point, unturned


def _joint_geometry(plant: MultibodyPlant, context, joint) -> tuple[np.ndarray, np.ndarray]:
    """(p_W, a_W): a revolute joint's point and unit axis in W at the context's (zero) angles."""
    X_WF = joint.frame_on_parent().CalcPoseInWorld(context)
    return X_WF.translation(), X_WF.rotation().matrix() @ joint.revolute_axis()


def _tip_radius(plant: MultibodyPlant, scene_graph: SceneGraph, frame, source: str) -> float:
    """The radius of the sphere whose centre is the tip frame's origin, on the frame's body."""
    inspector = scene_graph.model_inspector()
    X_BT = frame.GetFixedPoseInBodyFrame()
    for g in plant.GetCollisionGeometriesForBody(frame.body()):
        shape = inspector.GetShape(g)
        offset = inspector.GetPoseInFrame(g).translation() - X_BT.translation()
        if isinstance(shape, Sphere) and np.linalg.norm(offset) < 1e-9:
            return shape.radius()
    raise HandError(source, f"tip frame {frame.name()!r} has no collision sphere centred on it")


def _finger_chain(plant: MultibodyPlant, context, hand, finger: FingerEntry, source: str) -> SerialFinger:
    joints = []
    for name in finger.joints:
        if not plant.HasJointNamed(name, hand):
            raise HandError(source, f"joint {name!r} is not in the model")
        joints.append(plant.GetJointByName(name, hand))
    if not plant.HasFrameNamed(finger.tip, hand):
        raise HandError(source, f"tip frame {finger.tip!r} is not in the model")
    points, axes = zip(*(_joint_geometry(plant, context, j) for j in joints))
    return SerialFinger(
        p_W_joint=np.array(points),
        a_W=np.array(axes),
        p_W_tip0=plant.GetFrameByName(finger.tip, hand).CalcPoseInWorld(context).translation(),
        q_lower=np.array([j.position_lower_limits()[0] for j in joints]),
        q_upper=np.array([j.position_upper_limits()[0] for j in joints]),
    )


def build_space_scene(spec: str, *, mu: float, gravity: float, size=None, mass=None) -> SpaceScene:
    """The hand in space `spec` and its box (size and mass: given, else the YAML's object), finalized."""
    hand_file = space_hand_file(spec)
    own = hand_file.object
    size = size if size is not None else (own and own.size)
    mass = mass if mass is not None else (own and own.mass)
    if size is None or mass is None:
        raise HandError(hand_file.source, "names no object size and mass, and none was given")
    box = SpaceObject(size=tuple(float(s) for s in size), mass=float(mass), mu=mu)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    (hand,) = Parser(plant).AddModels(hand_file.model)
    instance = add_space_object(plant, box)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -gravity])
    plant.Finalize()
    diagram = builder.Build()
    context = plant.CreateDefaultContext()
    fingers = tuple(_finger_chain(plant, context, hand, f, hand_file.source) for f in hand_file.fingers)
    radii = {
        _tip_radius(plant, scene_graph, plant.GetFrameByName(f.tip, hand), hand_file.source) for f in hand_file.fingers
    }
    if len(radii) != 1:
        raise HandError(hand_file.source, f"the fingertip spheres differ in radius: {sorted(radii)} m")
    actuation = {
        plant.get_joint_actuator(a).joint().name(): plant.get_joint_actuator(a).effort_limit()
        for a in plant.GetJointActuatorIndices(hand)
    }
    tau_max = np.array([[actuation.get(n, np.inf) for n in f.joints] for f in hand_file.fingers])
    joint = plant.GetJointByName("box_floating")
    return SpaceScene(
        hand_file=hand_file,
        object=box,
        gravity=gravity,
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        hand=hand,
        box=instance,
        fingers=fingers,
        tip_radius=radii.pop(),
        tau_max=tau_max,
        hand_q_indices=np.array(
            [plant.GetJointByName(n, hand).position_start() for f in hand_file.fingers for n in f.joints]
        ),
        box_q_indices=np.arange(joint.position_start(), joint.position_start() + 7),
    )
