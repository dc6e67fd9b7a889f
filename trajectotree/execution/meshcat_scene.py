"""The Meshcat scene of a run, in the plane and in space: a loopback Meshcat server, the camera (above the
plane; in space, in front of the cube and above it), each fingertip in its finger's colour
(figures.legend.finger_rgb, as the PNG figures do) and the green outline of the planned object pose (the plan
ghost: the polygon's outline in the plane, the cube's edges in space, which draws the cube see-through).

Facts this module relies on (measured with drake 1.51): Meshcat serves on all interfaces
unless told `host="localhost"`; `Set2dRenderMode` with the camera above the plane gives a
stable view with +y up.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
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
GHOST_RGBA = Rgba(0.1, 0.7, 0.2, 1.0)  # the plan ghost's green
CUBE_ALPHA = 0.45  # the cube's opacity in space: the force arrows run from the fingertips into it
CAMERA_POSITION = (0.2, -0.2, 0.16)  # m, in space: looking at the grasp point from the front right, above


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


def tip_visual(plant, scene_graph, body):
    """The GeometryId of the fingertip sphere on `body` (the body of a finger's tip frame): its visual
    named "tip_visual", else its only sphere visual; None when it has neither (a model whose fingertip
    is drawn by a mesh)."""
    inspector = scene_graph.model_inspector()
    visuals = plant.GetVisualGeometriesForBody(body)
    found = [g for g in visuals if inspector.GetName(g).endswith("tip_visual")]
    if not found:
        found = [g for g in visuals if isinstance(inspector.GetShape(g), Sphere)]
    return found[0] if len(found) == 1 else None


def fingertip_visuals(plant, scene_graph, hand, description: HandDescription) -> list:
    """The fingertip sphere (tip_visual) of each finger of a planar hand."""
    return [tip_visual(plant, scene_graph, finger_bodies(plant, hand, f)[-1]) for f in description.fingers]


def space_fingertip_visuals(plant, scene_graph, hand, hand_file) -> list:
    """The fingertip sphere (tip_visual) of each finger of a hand in space (its HandFile names each tip frame)."""
    return [tip_visual(plant, scene_graph, plant.GetFrameByName(f.tip, hand).body()) for f in hand_file.fingers]


def set_diffuse(plant, scene_graph, geometry, rgba: Rgba) -> None:
    """`geometry`'s illustration (Meshcat) in the colour `rgba`."""
    inspector = scene_graph.model_inspector()
    properties = IllustrationProperties(inspector.GetIllustrationProperties(geometry))
    properties.UpdateProperty("phong", "diffuse", rgba)
    # removed and assigned anew: kReplace logs a warning meant for visualizers already running
    scene_graph.RemoveRole(plant.get_source_id(), geometry, Role.kIllustration)
    scene_graph.AssignRole(plant.get_source_id(), geometry, properties)


def color_geometries(plant, scene_graph, fingertips) -> None:
    """Gives each fingertip sphere (a GeometryId per finger, None: left alone) its finger's colour in every
    illustration (Meshcat) of this SceneGraph: the SDF's are one colour, the figures' one per finger."""
    for i, geometry in enumerate(fingertips):
        if geometry is not None:
            set_diffuse(plant, scene_graph, geometry, Rgba(*finger_rgb(i), 1.0))


def color_fingertips(plant, scene_graph, hand, description: HandDescription) -> None:
    """Each fingertip sphere of a planar hand in its finger's colour (color_geometries)."""
    color_geometries(plant, scene_graph, fingertip_visuals(plant, scene_graph, hand, description))


def see_through(plant, scene_graph, instance, alpha: float = CUBE_ALPHA) -> None:
    """The visuals of the model `instance` (the cube in space) at opacity `alpha`, their colour kept."""
    inspector = scene_graph.model_inspector()
    for body in plant.GetBodyIndices(instance):
        for g in plant.GetVisualGeometriesForBody(plant.get_body(body)):
            rgba = inspector.GetIllustrationProperties(g).GetPropertyOrDefault(
                "phong", "diffuse", Rgba(0.2, 0.45, 0.8, 1.0)
            )
            set_diffuse(plant, scene_graph, g, Rgba(rgba.r(), rgba.g(), rgba.b(), alpha))


def add_visualizer(
    builder: DiagramBuilder, plant, scene_graph, hand, description: HandDescription, meshcat: Meshcat
) -> MeshcatVisualizer:
    """A MeshcatVisualizer of `scene_graph` with each fingertip in its finger's colour (color_fingertips)."""
    color_fingertips(plant, scene_graph, hand, description)
    params = MeshcatVisualizerParams(publish_period=PUBLISH_PERIOD)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def add_space_visualizer(
    builder: DiagramBuilder, plant, scene_graph, hand, box, hand_file, meshcat: Meshcat
) -> MeshcatVisualizer:
    """A MeshcatVisualizer of a hand in space (`hand_file` its description) and its cube (model instance `box`,
    see-through), each fingertip in its finger's colour, the camera in front of the cube (set_space_view)."""
    color_geometries(plant, scene_graph, space_fingertip_visuals(plant, scene_graph, hand, hand_file))
    see_through(plant, scene_graph, box)
    set_space_view(meshcat)
    params = MeshcatVisualizerParams(publish_period=PUBLISH_PERIOD)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def set_space_view(meshcat: Meshcat) -> None:
    """Meshcat's perspective camera at CAMERA_POSITION, looking at the grasp point (W's origin), without Meshcat's
    grid and axes: the grid's plane z = 0 runs through the cube, the axes from its centre."""
    meshcat.SetCameraPose(np.array(CAMERA_POSITION), np.zeros(3))
    for path in ("/Grid", "/Axes"):
        meshcat.SetProperty(path, "visible", False)


def add_plan_ghost(meshcat: Meshcat, config: SceneConfig) -> None:
    """A green outline of the object (drawn above it) that shows the planned pose."""
    v = config.shape.vertices
    closed = np.vstack([v, v[:1]])
    outline = np.hstack([closed, np.full((len(closed), 1), config.box_depth / 2 + 1e-3)]).T
    meshcat.SetLine(PLAN_GHOST_PATH, outline, line_width=2.0, rgba=GHOST_RGBA)


def add_space_plan_ghost(meshcat: Meshcat, size) -> None:
    """The twelve edges of the cube of `size` (x, y, z) m in green, that show its planned pose in space."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    corners = signs * np.asarray(size, dtype=float) / 2
    edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(signs[a] != signs[b]) == 1]
    start, end = (np.array([corners[e[k]] for e in edges]).T for k in (0, 1))
    meshcat.SetLineSegments(PLAN_GHOST_PATH, start, end, line_width=2.0, rgba=GHOST_RGBA)


def pose_transform(pose) -> RigidTransform:
    """X_WB of an object pose: (x, y, theta) in the plane, [qw, qx, qy, qz, px, py, pz] in space."""
    if len(pose) == 7:
        quaternion = np.asarray(pose[:4], dtype=float)
        return RigidTransform(Quaternion(quaternion / np.linalg.norm(quaternion)), np.asarray(pose[4:], dtype=float))
    return RigidTransform(RotationMatrix.MakeZRotation(float(pose[2])), [float(pose[0]), float(pose[1]), 0.0])


def animate_plan_ghost(animation, times, poses) -> None:
    """Adds the planned object pose (pose_transform's, either kind) at `times` to a MeshcatAnimation."""
    for t, pose in zip(times, poses):
        animation.SetTransform(animation.frame(float(t)), PLAN_GHOST_PATH, pose_transform(pose))
