"""Each finger's force on the object as a Meshcat arrow in the finger's colour, at one scale per run
(figures.legend.arrow_newtons_per_cm): the arrows' geometry, their pose for given forces, and the
LeafSystem that draws the simulated forces live and into Meshcat's recording.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, Meshcat, Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem

from trajectotree.execution.meshcat_scene import PUBLISH_PERIOD
from trajectotree.figures.legend import finger_rgb, force_arrow
from trajectotree.scene.hand import HandDescription

FORCE_ARROWS_PATH = "/forces"
ARROW_Z = 0.05  # m, above the object (0.05 m deep: its top at 0.025 m), the fingertips and the plan outline
ARROW_SHAFT_WIDTH = 0.004  # m
ARROW_HEAD = 0.014  # m, head length and width; a shorter arrow's head shrinks to half its length


def add_force_arrows(meshcat: Meshcat, num_fingers: int) -> None:
    """One hidden arrow per finger in its colour at FORCE_ARROWS_PATH/finger{i}: a unit shaft
    along +x (scaled to length by set_force_arrows) and a flat head whose tip is its origin."""
    head = np.array([[0.0, -ARROW_HEAD, -ARROW_HEAD], [0.0, ARROW_HEAD / 2, -ARROW_HEAD / 2], [0.0, 0.0, 0.0]])
    for i in range(num_fingers):
        path, rgba = f"{FORCE_ARROWS_PATH}/finger{i}", Rgba(*finger_rgb(i), 1.0)
        meshcat.SetObject(f"{path}/shaft", Box(1.0, ARROW_SHAFT_WIDTH, 1e-3), rgba)
        meshcat.SetTriangleMesh(f"{path}/head", head, np.array([[0], [1], [2]], dtype=np.int32), rgba)
        meshcat.SetProperty(path, "visible", False)


def set_force_arrows(
    meshcat: Meshcat, tips, forces, tip_radius: float, newtons_per_cm: float, time: float | None = None
) -> None:
    """Points each finger's arrow (add_force_arrows) along its force on the object (forces (F, 2), N)
    from its fingertip (tips (F, 2), sphere centres), |f| / newtons_per_cm cm long (figures.run.force_arrow),
    hidden while the finger pushes less than ARROW_MIN_FORCE; recorded at `time` while Meshcat records."""
    for i, (tip, f) in enumerate(zip(tips, forces)):
        path = f"{FORCE_ARROWS_PATH}/finger{i}"
        arrow = force_arrow(tip, f, tip_radius, newtons_per_cm)
        if arrow is None:
            meshcat.SetProperty(path, "visible", False, time)
            continue
        start, end = arrow
        length = float(np.hypot(*(end - start)))
        head = min(ARROW_HEAD, length / 2)
        angle = math.atan2(end[1] - start[1], end[0] - start[0])
        meshcat.SetTransform(path, RigidTransform(RotationMatrix.MakeZRotation(angle), [*start, ARROW_Z]), time)
        meshcat.SetTransform(f"{path}/shaft", RigidTransform([(length - head) / 2, 0.0, 0.0]), time)
        meshcat.SetProperty(f"{path}/shaft/<object>", "scale", [length - head, 1.0, 1.0], time)
        meshcat.SetTransform(f"{path}/head", RigidTransform([length, 0.0, 0.0]), time)
        meshcat.SetProperty(f"{path}/head/<object>", "scale", [head / ARROW_HEAD] * 2 + [1.0], time)
        meshcat.SetProperty(path, "visible", True, time)


class ForceArrows(LeafSystem):
    """Draws each finger's force on the object (input "forces", 2F: the fingers' (f_x, f_y) in W,
    finger-major) as Meshcat arrows (set_force_arrows) every PUBLISH_PERIOD, at the fingertips of
    the plant's body poses (input "body_poses"): live, and into Meshcat's recording while it records."""

    def __init__(self, meshcat: Meshcat, plant, hand, description: HandDescription, newtons_per_cm: float):
        super().__init__()
        self._meshcat, self._newtons_per_cm = meshcat, newtons_per_cm
        self._tip_radius, self._num_fingers = description.tip_radius, description.num_fingers
        frames = [plant.GetFrameByName(f.tip_frame, hand) for f in description.fingers]
        self._tips = [(int(f.body().index()), f.GetFixedPoseInBodyFrame().translation()) for f in frames]
        self.forces_port = self.DeclareVectorInputPort("forces", 2 * self._num_fingers)
        self.body_poses_port = self.DeclareAbstractInputPort("body_poses", AbstractValue.Make([RigidTransform()]))
        self.DeclarePeriodicPublishEvent(PUBLISH_PERIOD, 0.0, self._publish)
        self.DeclareForcedPublishEvent(self._publish)
        add_force_arrows(meshcat, self._num_fingers)

    def _publish(self, context) -> None:
        poses = self.body_poses_port.Eval(context)
        tips = [poses[body].multiply(p_BF)[:2] for body, p_BF in self._tips]
        forces = np.asarray(self.forces_port.Eval(context)).reshape(self._num_fingers, 2)
        set_force_arrows(self._meshcat, tips, forces, self._tip_radius, self._newtons_per_cm, context.get_time())


def add_force_arrows_system(
    builder,
    plant,
    scene_graph,
    hand,
    description: HandDescription,
    meshcat: Meshcat,
    forces_port,
    newtons_per_cm: float,
):
    """A ForceArrows in `builder` reading `forces_port` (the fingers' forces on the object, 2F) and
    the plant's body poses."""
    arrows = builder.AddNamedSystem("force_arrows", ForceArrows(meshcat, plant, hand, description, newtons_per_cm))
    builder.Connect(forces_port, arrows.forces_port)
    builder.Connect(plant.get_body_poses_output_port(), arrows.body_poses_port)
    return arrows
