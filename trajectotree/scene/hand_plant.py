"""A hand in a MultibodyPlant: `add_hand` parses its model file into an unfinalized plant with the
contact friction asked for, welds its free bodies, adds a frame at each fingertip sphere's centre
and checks the fingers' names and chains (HandError naming the finger, the joint and the file);
`finger_bodies` and `tip_frame_name` find a finger's bodies and fingertip frame in such a plant.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import SceneGraph
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame

from trajectotree.scene.friction import set_friction
from trajectotree.scene.hand_file import MODELS_DIR, HandFile

ADDED_TIP_FRAME = "trajectotree_tip{i}"  # the frame add_hand adds at a fingertip sphere's centre (tip_xyz given)


def _parse_model(plant: MultibodyPlant, hand: HandFile, mu: float, scene_graph: SceneGraph | None):
    """Parses the model into `plant` with fingertip-and-link friction mu (friction.set_friction: it
    needs `scene_graph` when the plant registers geometry)."""
    parser = Parser(plant)
    parser.package_map().Add("trajectotree", str(MODELS_DIR))
    try:
        if hand.model.startswith("package://"):
            instances = parser.AddModels(url=hand.model)
        else:
            instances = parser.AddModels(hand.model)
    except RuntimeError as e:
        raise hand.error(f"Drake cannot parse its model {hand.model}: {e}") from None
    if len(instances) != 1:
        raise hand.error(f"its model {hand.model} holds {len(instances)} models; give a file with one")
    (instance,) = instances
    set_friction(plant, scene_graph, instance, mu)
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
