"""Watching runs: Meshcat (live, or recorded into a self-contained HTML file) and
a matplotlib GIF for places without WebGL.

Facts this module relies on (measured with drake 1.51): Meshcat serves on all interfaces
unless told `host="localhost"`; a recording reaches the HTML only after
`PublishRecording()`; `Set2dRenderMode` with the camera above the plane gives a
stable view with +y up; `StaticHtml()` inlines every script (no network).
"""

from __future__ import annotations

import json
import logging
import math
import os
from html import escape
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import Config, SceneConfig
from trajectotree.io import write_bytes_atomic
from trajectotree.scene.plant import add_hand_and_box

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


def add_visualizer(builder: DiagramBuilder, scene_graph, meshcat: Meshcat) -> MeshcatVisualizer:
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


# Legend entries (CSS swatch, text); the colours are the SDF's diffuse colours and the ghost's.
LEGEND_BOX = ("background: rgb(51, 115, 204)", "box")
LEGEND_PLANNED = ("border: 2px solid rgb(26, 178, 51)", "planned box pose (outline)")
LEGEND_FINGERS = (
    "background: linear-gradient(90deg, rgb(89, 89, 102) 60%, rgb(217, 89, 51) 60%)",
    "fingers 0-3: links (grey), fingertips (orange)",
)
SIMULATED_LEGEND = (LEGEND_BOX, LEGEND_PLANNED, LEGEND_FINGERS)


def object_noun(config: SceneConfig) -> str:
    """What the pages and figures call the object: "box", or "object" for any other polygon."""
    return "box" if config.shape.is_box else "object"


def simulated_legend(config: SceneConfig):
    """SIMULATED_LEGEND, naming the object by object_noun."""
    noun = object_noun(config)
    return ((LEGEND_BOX[0], noun), (LEGEND_PLANNED[0], f"planned {noun} pose (outline)"), LEGEND_FINGERS)


PAGE_SCRIPT = """
(function () {
  const HALF = %(half)s, DROP = %(drop)s, NOUN = %(noun)s;  // m, half-width of the view; s, drop time or null
  function ready() { return window.viewer && viewer.animator && viewer.camera; }
  function now() { return viewer.animator.actions.reduce((t, a) => Math.max(t, a.time), 0); }
  function centre() {  // Meshcat widens its orthographic view to the right only: keep the hand centred
    const c = viewer.camera, w = viewer.dom_element.offsetWidth, h = viewer.dom_element.offsetHeight;
    if (c.type !== "OrthographicCamera" || !w || !h) return;
    const sx = Math.max(w / h, 1), sy = Math.max(h / w, 1);
    c.left = -HALF * sx; c.right = HALF * sx; c.top = HALF * sy; c.bottom = -HALF * sy;
    c.updateProjectionMatrix(); viewer.set_dirty();
  }
  function tick() {
    const t = now(), d = viewer.animator.duration || 0;
    document.getElementById("tt-time").textContent = "t = " + t.toFixed(2) + " s of " + d.toFixed(2) + " s";
    document.getElementById("tt-bar-fill").style.width = (d ? 100 * Math.min(t / d, 1) : 0) + "%%";
    if (DROP !== null) {
      const mark = document.getElementById("tt-drop");
      mark.style.left = (d ? 100 * Math.min(DROP / d, 1) : 0) + "%%";
      const note = document.getElementById("tt-drop-note");
      note.textContent = NOUN + (t >= DROP ? " dropped at " : " drops at ") + DROP.toFixed(2) + " s";
      note.style.fontWeight = t >= DROP ? "bold" : "normal";
    }
    requestAnimationFrame(tick);
  }
  function start() {
    if (!ready()) { setTimeout(start, 100); return; }
    const resize = viewer.set_3d_pane_size.bind(viewer);
    viewer.set_3d_pane_size = function (w, h) { resize(w, h); centre(); };
    const setCamera = viewer.set_camera.bind(viewer);
    viewer.set_camera = function (c) { setCamera(c); centre(); };
    centre();
    tick();
  }
  start();
})();
"""
PAGE_CSS = """
#tt-overlay { position: fixed; left: 12px; top: 10px; font: 14px sans-serif; color: #222;
  background: rgba(255, 255, 255, 0.85); padding: 6px 10px; border-radius: 4px; z-index: 10; }
#tt-title { font-weight: bold; margin-bottom: 2px; }
#tt-bar { position: relative; width: 220px; height: 6px; background: #ddd; margin: 4px 0; }
#tt-bar-fill { position: absolute; left: 0; top: 0; height: 100%; background: #555; }
#tt-drop { position: absolute; top: -4px; width: 3px; height: 14px; margin-left: -1px; background: #d00; }
#tt-drop-note { color: #d00; }
#tt-legend { position: fixed; left: 12px; bottom: 10px; font: 13px sans-serif; color: #222;
  background: rgba(255, 255, 255, 0.85); padding: 6px 10px; border-radius: 4px; z-index: 10; }
.tt-swatch { display: inline-block; width: 22px; height: 10px; margin-right: 6px; vertical-align: middle;
  box-sizing: border-box; }
"""


def decorate_page(html: str, *, title: str, legend, drop_time_s: float | None = None, noun: str = "box") -> str:
    """Meshcat's static page with `title` (tab and overlay), a time readout and bar (the
    drop, if any, marked in red), a legend of (CSS swatch, text) entries, and the
    planar view kept centred in any window shape."""
    drop = "null" if drop_time_s is None else f"{float(drop_time_s):.6f}"
    marker = "" if drop_time_s is None else '<div id="tt-drop"></div>'
    note = "" if drop_time_s is None else '<div id="tt-drop-note"></div>'
    items = "".join(
        f'<div><span class="tt-swatch" style="{escape(style)}"></span>{escape(text)}</div>' for style, text in legend
    )
    overlay = (
        f'<style>{PAGE_CSS}</style><div id="tt-overlay"><div id="tt-title">{escape(title)}</div>'
        f'<div id="tt-time"></div><div id="tt-bar"><div id="tt-bar-fill"></div>{marker}</div>{note}</div>'
        f'<div id="tt-legend">{items}</div>'
        f"<script>{PAGE_SCRIPT % {'half': VIEW_HALF_WIDTH, 'drop': drop, 'noun': json.dumps(noun)}}</script>"
    )
    start, end = html.find("<title>"), html.find("</title>")
    if start >= 0 and end > start:
        html = html[:start] + f"<title>{escape(title)}</title>" + html[end + len("</title>") :]
    body_end = html.rfind("</body>")
    return html[:body_end] + overlay + html[body_end:] if body_end >= 0 else html + overlay


def save_recording_html(
    meshcat: Meshcat,
    visualizer: MeshcatVisualizer,
    path: str | Path,
    *,
    title: str = "TrajectoTree: simulated run",
    legend=SIMULATED_LEGEND,
    drop_time_s: float | None = None,
    noun: str = "box",
) -> None:
    """Stops the visualizer's recording, publishes it and writes the static HTML, with a
    title, a time readout (marking the drop at drop_time_s) and a legend (decorate_page)."""
    visualizer.StopRecording()
    visualizer.PublishRecording()
    page = decorate_page(meshcat.StaticHtml(), title=title, legend=legend, drop_time_s=drop_time_s, noun=noun)
    write_bytes_atomic(path, page.encode())


def write_pose_html(
    config: Config, times, object_poses, joint_angles, path: str | Path, meshcat: Meshcat | None = None
) -> None:
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
    noun = object_noun(config.scene)
    save_recording_html(
        meshcat,
        visualizer,
        path,
        title="TrajectoTree: planned trajectory",
        legend=(LEGEND_BOX[:1] + (f"{noun} (planned pose)",), LEGEND_FINGERS),
        noun=noun,
    )


def write_plan_html(plan, config: Config, path: str | Path, meshcat: Meshcat | None = None) -> None:
    """Plays the PLANNED trajectory of `plan` (a PlanResult or a Reference) in an HTML file."""
    from trajectotree.execution.reference import reference_from_plan
    from trajectotree.scene.plant import build_scene

    reference = reference_from_plan(plan, build_scene(config.scene))
    times = np.arange(0.0, reference.duration + 1e-9, PUBLISH_PERIOD)
    poses = reference.object_pose_at(times)
    q = np.stack([np.interp(times, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])], axis=1)
    write_pose_html(config, times, poses, q, path, meshcat)


def write_gif(
    scene, times, object_poses, joint_angles, path: str | Path, *, planned_poses=None, fps: float = 10.0
) -> None:
    """A matplotlib GIF (PillowWriter, no ffmpeg) of the object and hand, the planned pose as an outline."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    from trajectotree.figures.run import plot_hand, plot_object

    times = np.asarray(times)
    frames = np.unique(np.searchsorted(times, np.arange(times[0], times[-1] + 1e-9, 1.0 / fps)).clip(0, len(times) - 1))
    shape = scene.config.shape
    fig, ax = plt.subplots(figsize=(4, 4))

    def draw(k):
        ax.clear()
        ax.set_aspect("equal")
        ax.set_xlim(-VIEW_HALF_WIDTH, VIEW_HALF_WIDTH)
        ax.set_ylim(-VIEW_HALF_WIDTH, VIEW_HALF_WIDTH)
        if planned_poses is not None:
            plot_object(ax, shape, planned_poses[k], color="none", alpha=1.0, ls="--")
        plot_object(ax, shape, object_poses[k])
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
