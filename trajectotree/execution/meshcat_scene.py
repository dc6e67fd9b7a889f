"""The planar Meshcat scene of a run: a loopback Meshcat server, the camera above the plane, each
fingertip in its finger's colour (figures.legend.finger_rgb, as the PNG figures do) and the green
outline of the planned object pose (the plan ghost).

Facts this module relies on (measured with drake 1.51): Meshcat serves on all interfaces
unless told `host="localhost"`; `Set2dRenderMode` with the camera above the plane gives a
stable view with +y up.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from pydrake.geometry import (
    IllustrationProperties,
    Meshcat,
    MeshcatParams,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import SceneConfig
from trajectotree.figures.legend import finger_rgb
from trajectotree.scene.hand import HandDescription, finger_bodies

VIEW_HALF_WIDTH = 0.32  # m, the planar view shows [-0.32, 0.32]^2: the hand's full reach
PUBLISH_PERIOD = 1 / 32  # s, recorded frame period of the playback
PLAN_GHOST_PATH = "/plan/box"


def start_meshcat() -> Meshcat:
    """A Meshcat server on loopback only (a free port from 7000 up). Drake's "Meshcat
    listening for connections" line is muted: most servers only record a playback, and
    the commands that serve a live view (--meshcat) print its URL themselves."""
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        return Meshcat(MeshcatParams(host="localhost"))
    finally:
        logger.setLevel(level)


def set_planar_view(meshcat: Meshcat) -> None:
    """Orthographic camera above the x-y plane looking down -z, +y up."""
    meshcat.Set2dRenderMode(
        X_WC=RigidTransform(RotationMatrix.MakeXRotation(-math.pi / 2), [0.0, 0.0, 5.0]),
        xmin=-VIEW_HALF_WIDTH,
        xmax=VIEW_HALF_WIDTH,
        ymin=-VIEW_HALF_WIDTH,
        ymax=VIEW_HALF_WIDTH,
    )


def finger_css(i: int) -> str:
    """Finger i's colour as CSS, e.g. "rgb(214, 39, 40)"."""
    return "rgb({}, {}, {})".format(*(round(255 * c) for c in finger_rgb(i)))


def fingertip_visuals(plant, scene_graph, hand, description: HandDescription) -> list:
    """The GeometryId of each finger's fingertip sphere on the body of its tip frame: its visual
    named "tip_visual", else its only sphere visual; None for a finger that has neither (a model
    whose fingertip is drawn by a mesh)."""
    inspector = scene_graph.model_inspector()
    tips = []
    for f in description.fingers:
        visuals = plant.GetVisualGeometriesForBody(finger_bodies(plant, hand, f)[-1])
        found = [g for g in visuals if inspector.GetName(g).endswith("tip_visual")]
        if not found:
            found = [g for g in visuals if isinstance(inspector.GetShape(g), Sphere)]
        tips.append(found[0] if len(found) == 1 else None)
    return tips


def color_fingertips(plant, scene_graph, hand, description: HandDescription) -> None:
    """Gives each fingertip sphere its finger's colour in every illustration (Meshcat) of this
    SceneGraph: the SDF's are one orange, the figures' one colour per finger."""
    inspector = scene_graph.model_inspector()
    for i, geometry in enumerate(fingertip_visuals(plant, scene_graph, hand, description)):
        if geometry is None:
            continue
        properties = IllustrationProperties(inspector.GetIllustrationProperties(geometry))
        properties.UpdateProperty("phong", "diffuse", Rgba(*finger_rgb(i), 1.0))
        # removed and assigned anew: kReplace logs a warning meant for visualizers already running
        scene_graph.RemoveRole(plant.get_source_id(), geometry, Role.kIllustration)
        scene_graph.AssignRole(plant.get_source_id(), geometry, properties)


def add_visualizer(
    builder: DiagramBuilder, plant, scene_graph, hand, description: HandDescription, meshcat: Meshcat
) -> MeshcatVisualizer:
    """A MeshcatVisualizer of `scene_graph` with each fingertip in its finger's colour (color_fingertips)."""
    color_fingertips(plant, scene_graph, hand, description)
    params = MeshcatVisualizerParams(publish_period=PUBLISH_PERIOD)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def add_plan_ghost(meshcat: Meshcat, config: SceneConfig) -> None:
    """A green outline of the object (drawn above it) that shows the planned pose."""
    v = config.shape.vertices
    closed = np.vstack([v, v[:1]])
    outline = np.hstack([closed, np.full((len(closed), 1), config.box_depth / 2 + 1e-3)]).T
    meshcat.SetLine(PLAN_GHOST_PATH, outline, line_width=2.0, rgba=Rgba(0.1, 0.7, 0.2, 1.0))


def pose_transform(pose) -> RigidTransform:
    """X_WB of an object pose (x, y, theta)."""
    return RigidTransform(RotationMatrix.MakeZRotation(float(pose[2])), [float(pose[0]), float(pose[1]), 0.0])


def animate_plan_ghost(animation, times, poses) -> None:
    """Adds the planned box pose (x, y, theta) at `times` to a MeshcatAnimation."""
    for t, pose in zip(times, poses):
        animation.SetTransform(animation.frame(float(t)), PLAN_GHOST_PATH, pose_transform(pose))
