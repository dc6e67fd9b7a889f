"""The hand: `load_hand(spec)` reads a hand's description file (trajectotree.scene.hand_file), adds
its model to a plant of its own (trajectotree.scene.hand_plant) and reads the `HandDescription` from
it (trajectotree.scene.hand_model). The names of those three modules are re-exported here, so that
`from trajectotree.scene.hand import X` serves every user of the hand.
"""

from __future__ import annotations

from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import DEFAULT_HAND
from trajectotree.scene.hand_file import (
    JOINTS_PER_FINGER,
    MIN_FINGERS,
    MODEL_SUFFIXES,
    MODELS_DIR,
    SHAPE_FIELDS,
    YAML_SUFFIXES,
    FingerEntry,
    HandError,
    HandFile,
    HandObject,
    HandYaml,
    Plane,
    Weld,
    hand_file,
    hand_yaml_path,
    with_hand_object,
)
from trajectotree.scene.hand_model import (
    PLANE_TOLERANCE,
    FingerDescription,
    FingerGeometry,
    HandDescription,
    LinkRectangle,
    read_hand,
)
from trajectotree.scene.hand_plant import ADDED_TIP_FRAME, add_hand, finger_bodies, tip_frame_name

__all__ = [
    "ADDED_TIP_FRAME",
    "JOINTS_PER_FINGER",
    "MIN_FINGERS",
    "MODEL_SUFFIXES",
    "MODELS_DIR",
    "PLANE_TOLERANCE",
    "SHAPE_FIELDS",
    "YAML_SUFFIXES",
    "FingerDescription",
    "FingerEntry",
    "FingerGeometry",
    "HandDescription",
    "HandError",
    "HandFile",
    "HandObject",
    "HandYaml",
    "LinkRectangle",
    "Plane",
    "Weld",
    "add_hand",
    "finger_bodies",
    "hand_file",
    "hand_yaml_path",
    "load_hand",
    "read_hand",
    "tip_frame_name",
    "with_hand_object",
]


def load_hand(spec: str = DEFAULT_HAND, mu: float = 0.7) -> HandDescription:
    """The description of hand `spec`, from a plant of its own (the hand alone, no gravity needed)."""
    hand = hand_file(spec)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    instance = add_hand(plant, hand, mu, scene_graph)
    plant.Finalize()
    return read_hand(plant, scene_graph, instance, hand)
