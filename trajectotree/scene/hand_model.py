"""A planar hand as data: `HandDescription`, its fingers' geometry (`FingerGeometry`: the closed-form
kinematics' base, angles and link lengths, torque limits, link masses and inertias, the fingertip
sphere and the links' collision boxes), read by `read_hand` from a finalized plant holding the hand's
model (added by trajectotree.scene.hand_plant.add_hand), at zero joint angles. A model that does not
fit (a finger joint off the plane, a free base, a missing fingertip sphere) raises HandError naming
the finger, the joint and the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant

from trajectotree.geometry import rotation_2d
from trajectotree.scene.hand_file import JOINTS_PER_FINGER, HandFile
from trajectotree.scene.hand_plant import tip_frame_name
from trajectotree.scene.kinematics import TwoLinkFinger

PLANE_TOLERANCE = 1e-9  # m or rad: how far a finger's joints, links and tip may lie off the plane


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
