"""Watching runs: Meshcat (live, or recorded into a self-contained HTML file) and
a matplotlib GIF for places without WebGL.

Facts this module relies on (DESIGN.md sec. 7): Meshcat serves on all interfaces
unless told `host="localhost"`; a recording reaches the HTML only after
`PublishRecording()`; `Set2dRenderMode` with the camera above the plane gives a
stable view with +y up; `StaticHtml()` inlines every script (no network).
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import Config, SceneConfig
from trajectotree.io import write_bytes_atomic
from trajectotree.scene import add_hand_and_box

VIEW_HALF_WIDTH = 0.32   # m, the planar view shows [-0.32, 0.32]^2: the hand's full reach
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
    meshcat.Set2dRenderMode(X_WC=RigidTransform(RotationMatrix.MakeXRotation(-math.pi / 2), [0.0, 0.0, 5.0]),
                            xmin=-VIEW_HALF_WIDTH, xmax=VIEW_HALF_WIDTH, ymin=-VIEW_HALF_WIDTH, ymax=VIEW_HALF_WIDTH)


def add_visualizer(builder: DiagramBuilder, scene_graph, meshcat: Meshcat) -> MeshcatVisualizer:
    params = MeshcatVisualizerParams(publish_period=PUBLISH_PERIOD)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def add_plan_ghost(meshcat: Meshcat, config: SceneConfig) -> None:
    """A green outline of the box (drawn above it) that shows the planned pose."""
    a, b, z = config.box_width / 2, config.box_height / 2, config.box_depth / 2 + 1e-3
    outline = np.array([[a, -b, z], [a, b, z], [-a, b, z], [-a, -b, z], [a, -b, z]]).T
    meshcat.SetLine(PLAN_GHOST_PATH, outline, line_width=2.0, rgba=Rgba(0.1, 0.7, 0.2, 1.0))


def pose_transform(pose) -> RigidTransform:
    """X_WB of an object pose (x, y, theta)."""
    return RigidTransform(RotationMatrix.MakeZRotation(float(pose[2])), [float(pose[0]), float(pose[1]), 0.0])


def animate_plan_ghost(animation, times, poses) -> None:
    """Adds the planned box pose (x, y, theta) at `times` to a MeshcatAnimation."""
    for t, pose in zip(times, poses):
        animation.SetTransform(animation.frame(float(t)), PLAN_GHOST_PATH, pose_transform(pose))


def save_recording_html(meshcat: Meshcat, visualizer: MeshcatVisualizer, path: str | Path) -> None:
    """Stops the visualizer's recording, publishes it and writes the static HTML."""
    visualizer.StopRecording()
    visualizer.PublishRecording()
    write_bytes_atomic(path, meshcat.StaticHtml().encode())


def write_pose_html(config: Config, times, object_poses, joint_angles, path: str | Path,
                    meshcat: Meshcat | None = None) -> None:
    """HTML playback of given poses without physics: each sample is published at
    its time with set_transforms_while_recording=False (the plan's trajectory)."""
    meshcat = meshcat or start_meshcat()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    hand, box = add_hand_and_box(plant, config.scene)
    plant.Finalize()
    visualizer = add_visualizer(builder, scene_graph, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    set_planar_view(meshcat)
    visualizer.StartRecording(set_transforms_while_recording=False)
    for t, pose, q in zip(times, object_poses, joint_angles):
        context.SetTime(float(t))
        plant.SetPositions(plant_context, box, pose)
        plant.SetPositions(plant_context, hand, q)
        diagram.ForcedPublish(context)
    save_recording_html(meshcat, visualizer, path)


def write_plan_html(plan, config: Config, path: str | Path, meshcat: Meshcat | None = None) -> None:
    """Plays the PLANNED trajectory of `plan` (a PlanResult or a Reference) in an HTML file."""
    from trajectotree.reference import reference_from_plan
    from trajectotree.scene import build_scene
    reference = reference_from_plan(plan, build_scene(config.scene))
    times = np.arange(0.0, reference.duration + 1e-9, PUBLISH_PERIOD)
    poses = reference.object_pose_at(times)
    q = np.stack([np.interp(times, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])], axis=1)
    write_pose_html(config, times, poses, q, path, meshcat)


def write_gif(scene, times, object_poses, joint_angles, path: str | Path, *, planned_poses=None,
              fps: float = 10.0) -> None:
    """A matplotlib GIF (PillowWriter, no ffmpeg) of the box and hand, the planned box as an outline."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    from trajectotree.plotting import plot_box, plot_hand
    times = np.asarray(times)
    frames = np.unique(np.searchsorted(times, np.arange(times[0], times[-1] + 1e-9, 1.0 / fps)).clip(0, len(times) - 1))
    c = scene.config
    fig, ax = plt.subplots(figsize=(4, 4))

    def draw(k):
        ax.clear()
        ax.set_aspect("equal")
        ax.set_xlim(-VIEW_HALF_WIDTH, VIEW_HALF_WIDTH)
        ax.set_ylim(-VIEW_HALF_WIDTH, VIEW_HALF_WIDTH)
        if planned_poses is not None:
            plot_box(ax, c.box_width, c.box_height, planned_poses[k], color="none", alpha=1.0, ls="--")
        plot_box(ax, c.box_width, c.box_height, object_poses[k])
        plot_hand(ax, scene, joint_angles[k])
        ax.set_title(f"t = {times[k]:.2f} s")

    animation = FuncAnimation(fig, draw, frames=frames)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    try:
        animation.save(tmp, writer=PillowWriter(fps=fps))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)
