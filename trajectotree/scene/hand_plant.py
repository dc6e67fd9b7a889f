"""A hand in a MultibodyPlant: `add_hand` parses its model file into an unfinalized plant with the
contact friction asked for, welds its free bodies, adds a frame at each fingertip sphere's centre
and checks the fingers' names and chains (HandError naming the finger, the joint and the file);
`finger_bodies` and `tip_frame_name` find a finger's bodies and fingertip frame in such a plant.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from pydrake.geometry import RoleAssign, SceneGraph
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame

from trajectotree.scene.hand_file import MODELS_DIR, HandFile

ADDED_TIP_FRAME = "trajectotree_tip{i}"  # the frame add_hand adds at a fingertip sphere's centre (tip_xyz given)
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


def finger_bodies(plant: MultibodyPlant, instance, finger) -> tuple:
    """The bodies of `finger` in a plant with the hand's model: its two links and, where its tip
    frame sits on another body (Drake's gripper: a tip link welded to link 2, which carries the
    fingertip sphere), that body too, from the base out."""
    bodies = [plant.GetBodyByName(name, instance) for name in finger.link_bodies]
    tip = plant.GetFrameByName(finger.tip_frame, instance).body()
    if tip.index() not in [b.index() for b in bodies]:
        bodies.append(tip)
    return tuple(bodies)
