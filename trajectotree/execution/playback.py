"""Watching runs: Meshcat (live, or recorded into a self-contained HTML file) and
a matplotlib GIF for places without WebGL. Both show each fingertip in its finger's
colour (figures.run.FINGER_COLORS, as the PNG figures do) and each finger's force on the
object as an arrow in that colour, at one scale per run (figures.run.arrow_newtons_per_cm)
that the page's legend and the GIF state; the page also numbers the fingers at their bases.

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
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Box,
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
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from trajectotree.config import Config, SceneConfig
from trajectotree.figures.legend import arrow_newtons_per_cm, arrow_scale_text, finger_rgb, force_arrow
from trajectotree.io import write_bytes_atomic
from trajectotree.scene.hand import HandDescription, finger_bodies, hand_file, read_hand
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
LEGEND_LINKS = ("background: rgb(89, 89, 102); height: 5px", "finger links")


def object_noun(config: SceneConfig) -> str:
    """What the pages and figures call the object: "box", or "object" for any other polygon."""
    return "box" if config.shape.is_box else "object"


def arrows_swatch(num_fingers: int) -> str:
    """A legend swatch of the force arrows: a bar in the fingers' colours."""
    width = 100 / num_fingers
    stops = ", ".join(f"{finger_css(i)} {width * i:g}% {width * (i + 1):g}%" for i in range(num_fingers))
    return f"background: linear-gradient(90deg, {stops}); height: 4px"


def arrows_legend(newtons_per_cm: float, which: str, num_fingers: int, noun: str = "box"):
    """The legend entry of the force arrows of `num_fingers` fingers: `which` forces ("simulated",
    "planned") at the stated scale."""
    return (
        arrows_swatch(num_fingers),
        f"arrow: {which} force of each finger on the {noun}, {arrow_scale_text(newtons_per_cm)}",
    )


def simulated_legend(config: SceneConfig, newtons_per_cm: float | None = None, num_fingers: int = 0):
    """The simulated run's legend, naming the object by object_noun; with the arrows' scale, their
    entry (for `num_fingers` fingers)."""
    noun = object_noun(config)
    entries = [(LEGEND_BOX[0], noun), (LEGEND_PLANNED[0], f"planned {noun} pose (outline)"), LEGEND_LINKS]
    if newtons_per_cm is not None:
        entries.append(arrows_legend(newtons_per_cm, "simulated", num_fingers, noun))
    return tuple(entries)


SIMULATED_LEGEND = simulated_legend(SceneConfig())


def finger_labels(plant, hand, description: HandDescription, *, offset: float = 0.03):
    """(text, CSS colour, x, y) of each finger's number, `offset` m outside its base (radially from W's origin)."""
    context = plant.CreateDefaultContext()
    labels = []
    for i, f in enumerate(description.fingers):
        joint = plant.GetJointByName(f.joints[0], hand)
        base = joint.frame_on_child().CalcPoseInWorld(context).translation()[:2]
        x, y = base * (1 + offset / max(float(np.hypot(*base)), 1e-9))
        labels.append((str(i), finger_css(i), float(x), float(y)))
    return labels


PAGE_SCRIPT = """
(function () {
  const HALF = %(half)s, DROP = %(drop)s, NOUN = %(noun)s;  // m, half-width of the view; s, drop time or null
  const LABELS = %(labels)s;  // [text, CSS colour, x m, y m]: the finger numbers, at their bases in W
  function ready() { return window.viewer && viewer.animator && viewer.camera; }
  function now() { return viewer.animator.actions.reduce((t, a) => Math.max(t, a.time), 0); }
  function centre() {  // Meshcat widens its orthographic view to the right only: keep the hand centred
    const c = viewer.camera, w = viewer.dom_element.offsetWidth, h = viewer.dom_element.offsetHeight;
    if (c.type !== "OrthographicCamera" || !w || !h) return;
    const sx = Math.max(w / h, 1), sy = Math.max(h / w, 1);
    c.left = -HALF * sx; c.right = HALF * sx; c.top = HALF * sy; c.bottom = -HALF * sy;
    c.updateProjectionMatrix(); viewer.set_dirty();
  }
  function place() {  // each label where the camera draws its point, so that it follows a zoom or a pan
    const r = viewer.dom_element.getBoundingClientRect(), c = viewer.camera;
    const root = viewer.scene_tree.object;  // Drake's W, z up, in three.js's y-up scene
    c.updateMatrixWorld();
    root.updateMatrixWorld();
    LABELS.forEach(function (label, k) {
      const v = root.localToWorld(new MeshCat.THREE.Vector3(label[2], label[3], 0)).project(c);
      const e = document.getElementById("tt-label-" + k);
      e.style.left = (r.left + (v.x + 1) / 2 * r.width) + "px";
      e.style.top = (r.top + (1 - v.y) / 2 * r.height) + "px";
      e.style.display = Math.abs(v.x) <= 1 && Math.abs(v.y) <= 1 ? "block" : "none";
    });
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
    place();
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
.tt-dot { display: inline-block; width: 11px; height: 11px; border-radius: 50%; margin: 0 3px 0 8px;
  vertical-align: middle; }
.tt-label { position: fixed; display: none; transform: translate(-50%, -50%); font: bold 16px sans-serif;
  text-shadow: 0 0 3px #fff, 0 0 3px #fff; pointer-events: none; z-index: 9; }
"""


def fingers_line(num_fingers: int) -> str:
    """The legend's line of fingertip colours, e.g. "fingertips ● 0 ● 1 ● 2 ● 3 (numbered at their bases)"."""
    dots = "".join(f' <span class="tt-dot" style="background: {finger_css(i)}"></span>{i}' for i in range(num_fingers))
    return f'<div id="tt-fingers">fingertips{dots} (numbered at their bases)</div>'


def decorate_page(
    html: str, *, title: str, legend, drop_time_s: float | None = None, noun: str = "box", labels=()
) -> str:
    """Meshcat's static page with `title` (tab and overlay), a time readout and bar (the
    drop, if any, marked in red), a legend of (CSS swatch, text) entries after the line of
    fingertip colours (one per label), the `labels` (text, CSS colour, x, y) at their points of the plane
    (finger_labels), and the planar view kept centred in any window shape."""
    drop = "null" if drop_time_s is None else f"{float(drop_time_s):.6f}"
    marker = "" if drop_time_s is None else '<div id="tt-drop"></div>'
    note = "" if drop_time_s is None else '<div id="tt-drop-note"></div>'
    items = fingers_line(len(labels)) + "".join(
        f'<div><span class="tt-swatch" style="{escape(style)}"></span>{escape(text)}</div>' for style, text in legend
    )
    marks = "".join(
        f'<div class="tt-label" id="tt-label-{k}" style="color: {escape(color)}">{escape(text)}</div>'
        for k, (text, color, _, _) in enumerate(labels)
    )
    script = PAGE_SCRIPT % {
        "half": VIEW_HALF_WIDTH,
        "drop": drop,
        "noun": json.dumps(noun),
        "labels": json.dumps([list(label) for label in labels]),
    }
    overlay = (
        f'<style>{PAGE_CSS}</style><div id="tt-overlay"><div id="tt-title">{escape(title)}</div>'
        f'<div id="tt-time"></div><div id="tt-bar"><div id="tt-bar-fill"></div>{marker}</div>{note}</div>'
        f'<div id="tt-legend">{items}</div>{marks}'
        f"<script>{script}</script>"
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
    labels=(),
) -> None:
    """Stops the visualizer's recording, publishes it and writes the static HTML, with a
    title, a time readout (marking the drop at drop_time_s), a legend and the finger
    numbers (`labels`, finger_labels) (decorate_page)."""
    visualizer.StopRecording()
    visualizer.PublishRecording()
    page = decorate_page(
        meshcat.StaticHtml(), title=title, legend=legend, drop_time_s=drop_time_s, noun=noun, labels=labels
    )
    write_bytes_atomic(path, page.encode())


def write_pose_html(
    config: Config,
    times,
    object_poses,
    joint_angles,
    path: str | Path,
    meshcat: Meshcat | None = None,
    forces=None,
    newtons_per_cm: float | None = None,
) -> None:
    """HTML playback of given poses without physics: each sample is published at
    its time with set_transforms_while_recording=False (the plan's trajectory); with
    `forces` (T, 4, 2), each finger's force on the object as an arrow at `newtons_per_cm`
    (default: arrow_newtons_per_cm of the forces)."""
    meshcat = meshcat or start_meshcat()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    hand, box = add_hand_and_box(plant, config.scene, scene_graph)
    plant.Finalize()
    description = read_hand(plant, scene_graph, hand, hand_file(config.scene.hand))
    visualizer = add_visualizer(builder, plant, scene_graph, hand, description, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    set_planar_view(meshcat)
    noun = object_noun(config.scene)
    legend = [(LEGEND_BOX[0], f"{noun} (planned pose)"), LEGEND_LINKS]
    if forces is not None:
        newtons_per_cm = newtons_per_cm or arrow_newtons_per_cm(forces)
        tip_radius = description.tip_radius
        tip_frames = [plant.GetFrameByName(f.tip_frame, hand) for f in description.fingers]
        add_force_arrows(meshcat, description.num_fingers)
        legend.append(arrows_legend(newtons_per_cm, "planned", description.num_fingers, noun))
    visualizer.StartRecording(set_transforms_while_recording=False)
    for k, (t, pose, q) in enumerate(zip(times, object_poses, joint_angles)):
        context.SetTime(float(t))
        plant.SetPositions(plant_context, box, pose)
        plant.SetPositions(plant_context, hand, q)
        diagram.ForcedPublish(context)
        if forces is not None:
            tips = [frame.CalcPoseInWorld(plant_context).translation()[:2] for frame in tip_frames]
            set_force_arrows(meshcat, tips, forces[k], tip_radius, newtons_per_cm, float(t))
    save_recording_html(
        meshcat,
        visualizer,
        path,
        title="TrajectoTree: planned trajectory",
        legend=tuple(legend),
        noun=noun,
        labels=finger_labels(plant, hand, description),
    )


def write_plan_html(plan, config: Config, path: str | Path, meshcat: Meshcat | None = None) -> None:
    """Plays the PLANNED trajectory of `plan` (a PlanResult or a Reference) in an HTML file,
    each finger's planned force on the object as an arrow."""
    from trajectotree.execution.reference import reference_from_plan
    from trajectotree.scene.plant import build_scene

    reference = reference_from_plan(plan, build_scene(config.scene))
    times = np.arange(0.0, reference.duration + 1e-9, PUBLISH_PERIOD)
    poses = reference.object_pose_at(times)
    q = np.stack([np.interp(times, reference.t, reference.q[:, j]) for j in range(reference.q.shape[1])], axis=1)
    forces = reference.forces_at(times)
    write_pose_html(config, times, poses, q, path, meshcat, forces=forces, newtons_per_cm=arrow_newtons_per_cm(forces))


GIF_DPI = 120  # the GIF's frames: 552 px wide, its labels readable on a README page


def write_gif(
    scene,
    times,
    object_poses,
    joint_angles,
    path: str | Path,
    *,
    planned_poses=None,
    forces=None,
    newtons_per_cm: float | None = None,
    fps: float = 10.0,
    title: str | None = None,
) -> None:
    """A matplotlib GIF (PillowWriter, no ffmpeg) of the object and hand on x, y axes in m, the
    fingers numbered and coloured as in the figures, the planned pose as a dashed outline, each
    finger's force on the object (`forces` (T, 4, 2)) as an arrow at `newtons_per_cm` (default:
    arrow_newtons_per_cm of the forces), the time of each frame and a `title` above it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    from trajectotree.figures.run import plot_run_frame

    times = np.asarray(times)
    frames = np.unique(np.searchsorted(times, np.arange(times[0], times[-1] + 1e-9, 1.0 / fps)).clip(0, len(times) - 1))
    if forces is not None and newtons_per_cm is None:
        newtons_per_cm = arrow_newtons_per_cm(forces)
    noun = object_noun(scene.config)
    notes = ([f"dashed: planned {noun} pose"] if planned_poses is not None else []) + (
        [f"arrows: each finger's force on the {noun}, {arrow_scale_text(newtons_per_cm)}"] if forces is not None else []
    )
    fig, ax = plt.subplots(figsize=(4.6, 4.6 + 0.18 * len(notes)))

    def draw(k):
        ax.clear()
        clock = f"t = {times[k]:.2f} s of {times[-1]:.2f} s"
        plot_run_frame(
            ax,
            scene,
            object_poses[k],
            joint_angles[k],
            half_width=VIEW_HALF_WIDTH,
            planned_pose=None if planned_poses is None else planned_poses[k],
            forces=None if forces is None else forces[k],
            newtons_per_cm=newtons_per_cm,
            title=f"{title}\n{clock}" if title else clock,
        )

    if notes:
        fig.text(0.5, 0.01, "\n".join(notes), ha="center", va="bottom", fontsize=7.5, color="0.25")
    draw(frames[0])
    fig.tight_layout(rect=(0, 0.045 * len(notes), 1, 1))
    animation = FuncAnimation(fig, draw, frames=frames)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    try:
        animation.save(tmp, writer=PillowWriter(fps=fps), dpi=GIF_DPI)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)
