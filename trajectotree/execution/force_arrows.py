"""Each finger's force on the object as a Meshcat arrow in the finger's colour, at one scale per run
(figures.legend.arrow_newtons_per_cm), in the plane or in space: the arrows' geometry (flat in the plane, drawn
above the object; solid in space, seen from any side), their pose for given forces, and the LeafSystem that
draws the simulated forces live and into Meshcat's recording.
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
PYRAMID_CORNERS = ((1, 1), (-1, 1), (-1, -1), (1, -1))  # (y, z) signs of a solid head's base, in turn


# An arrow head whose tip is its origin, pointing along +x, ARROW_HEAD long and wide: (vertices (3, N) m,
# triangles (3, M)). Flat in the plane; a four-sided pyramid in space.
FLAT_HEAD = (
    np.array([[0.0, -ARROW_HEAD, -ARROW_HEAD], [0.0, ARROW_HEAD / 2, -ARROW_HEAD / 2], [0.0, 0.0, 0.0]]),
    np.array([[0], [1], [2]], dtype=np.int32),
)
PYRAMID_HEAD = (
    np.array(
        [[0.0, 0.0, 0.0]] + [[-ARROW_HEAD, sy * ARROW_HEAD / 2, sz * ARROW_HEAD / 2] for sy, sz in PYRAMID_CORNERS]
    ).T,
    np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [1, 3, 2], [1, 4, 3]], dtype=np.int32).T,
)


def add_force_arrows(meshcat: Meshcat, num_fingers: int, dimensions: int = 2) -> None:
    """One hidden arrow per finger in its colour at FORCE_ARROWS_PATH/finger{i}: a unit shaft along +x (scaled
    to length by set_force_arrows) and a head whose tip is its origin; flat in the plane (`dimensions` 2),
    solid in space (3)."""
    thickness, (vertices, faces) = (1e-3, FLAT_HEAD) if dimensions == 2 else (ARROW_SHAFT_WIDTH, PYRAMID_HEAD)
    for i in range(num_fingers):
        path, rgba = f"{FORCE_ARROWS_PATH}/finger{i}", Rgba(*finger_rgb(i), 1.0)
        meshcat.SetObject(f"{path}/shaft", Box(1.0, ARROW_SHAFT_WIDTH, thickness), rgba)
        meshcat.SetTriangleMesh(f"{path}/head", vertices, faces, rgba)
        meshcat.SetProperty(path, "visible", False)


def arrow_pose(start, end) -> RigidTransform:
    """X_WA of an arrow from `start` to `end` (2,) in the plane, at height ARROW_Z, or (3,) in space: its
    origin at `start`, its x along the arrow."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    if len(start) == 2:
        angle = math.atan2(end[1] - start[1], end[0] - start[0])
        return RigidTransform(RotationMatrix.MakeZRotation(angle), [*start, ARROW_Z])
    x = (end - start) / np.linalg.norm(end - start)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, np.cross(x, y)])), start)


def set_force_arrows(
    meshcat: Meshcat, tips, forces, tip_radius: float, newtons_per_cm: float, time: float | None = None
) -> None:
    """Points each finger's arrow (add_force_arrows) along its force on the object (forces (F, 2) in the
    plane, (F, 3) in space, N) from its fingertip (tips (F, 2) or (F, 3), sphere centres), |f| / newtons_per_cm
    cm long (figures.legend.force_arrow), hidden while the finger pushes less than ARROW_MIN_FORCE; recorded at
    `time` while Meshcat records."""
    for i, (tip, f) in enumerate(zip(tips, forces)):
        path = f"{FORCE_ARROWS_PATH}/finger{i}"
        arrow = force_arrow(tip, f, tip_radius, newtons_per_cm)
        if arrow is None:
            meshcat.SetProperty(path, "visible", False, time)
            continue
        start, end = arrow
        length = float(np.linalg.norm(end - start))
        head = min(ARROW_HEAD, length / 2)
        meshcat.SetTransform(path, arrow_pose(start, end), time)
        meshcat.SetTransform(f"{path}/shaft", RigidTransform([(length - head) / 2, 0.0, 0.0]), time)
        meshcat.SetProperty(f"{path}/shaft/<object>", "scale", [length - head, 1.0, 1.0], time)
        meshcat.SetTransform(f"{path}/head", RigidTransform([length, 0.0, 0.0]), time)
        meshcat.SetProperty(f"{path}/head/<object>", "scale", [head / ARROW_HEAD] * 3, time)
        meshcat.SetProperty(path, "visible", True, time)


class ForceArrows(LeafSystem):
    """Draws each finger's force on the object (input "forces", dF: the fingers' forces in W, finger-major,
    d = `dimensions`: (f_x, f_y) in the plane, (f_x, f_y, f_z) in space) as Meshcat arrows (set_force_arrows)
    every PUBLISH_PERIOD, at the origins of the fingertip frames `tip_frames` (the sphere centres) in the
    plant's body poses (input "body_poses"): live, and into Meshcat's recording while it records."""

    def __init__(self, meshcat: Meshcat, tip_frames, tip_radius: float, newtons_per_cm: float, dimensions: int = 2):
        super().__init__()
        self._meshcat, self._newtons_per_cm, self._dimensions = meshcat, newtons_per_cm, dimensions
        self._tip_radius, self._num_fingers = tip_radius, len(tip_frames)
        self._tips = [(int(f.body().index()), f.GetFixedPoseInBodyFrame().translation()) for f in tip_frames]
        self.forces_port = self.DeclareVectorInputPort("forces", dimensions * self._num_fingers)
        self.body_poses_port = self.DeclareAbstractInputPort("body_poses", AbstractValue.Make([RigidTransform()]))
        self.DeclarePeriodicPublishEvent(PUBLISH_PERIOD, 0.0, self._publish)
        self.DeclareForcedPublishEvent(self._publish)
        add_force_arrows(meshcat, self._num_fingers, dimensions)

    def _publish(self, context) -> None:
        poses = self.body_poses_port.Eval(context)
        tips = [poses[body].multiply(p_BF)[: self._dimensions] for body, p_BF in self._tips]
        forces = np.asarray(self.forces_port.Eval(context)).reshape(self._num_fingers, self._dimensions)
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
    frames = [plant.GetFrameByName(f.tip_frame, hand) for f in description.fingers]
    arrows = ForceArrows(meshcat, frames, description.tip_radius, newtons_per_cm)
    return connect_force_arrows(builder, plant, arrows, forces_port)


def add_space_force_arrows_system(builder, plant, hand, scene, meshcat: Meshcat, forces_port, newtons_per_cm: float):
    """A ForceArrows in space in `builder` reading `forces_port` (the fingers' forces on the cube, 3F) and the
    plant's body poses, at the tip frames that `scene` (scene.spatial.SpaceScene) names on the model instance
    `hand` of `plant`."""
    frames = [plant.GetFrameByName(f.tip, hand) for f in scene.hand_file.fingers]
    arrows = ForceArrows(meshcat, frames, scene.tip_radius, newtons_per_cm, dimensions=3)
    return connect_force_arrows(builder, plant, arrows, forces_port)


def connect_force_arrows(builder, plant, arrows: ForceArrows, forces_port):
    """`arrows` added to `builder` as "force_arrows", reading `forces_port` and the plant's body poses."""
    arrows = builder.AddNamedSystem("force_arrows", arrows)
    builder.Connect(forces_port, arrows.forces_port)
    builder.Connect(plant.get_body_poses_output_port(), arrows.body_poses_port)
    return arrows
