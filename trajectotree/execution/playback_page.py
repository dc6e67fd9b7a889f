"""The playback page, in the plane and in space: Meshcat's self-contained HTML (`StaticHtml()` inlines every
script, no network) with a title, a time readout and bar (the drop marked), a legend of the object, the plan
outline, the links and the force arrows, and each finger's number at its base.

Facts this module relies on (measured with drake 1.51): a recording reaches the HTML only after
`PublishRecording()`.
"""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer

from trajectotree.config import SceneConfig
from trajectotree.execution.meshcat_scene import VIEW_HALF_WIDTH, finger_css
from trajectotree.figures.legend import arrow_scale_text
from trajectotree.io import write_bytes_atomic
from trajectotree.scene.hand import HandDescription

# Legend entries (CSS swatch, text); the colours are the SDF's diffuse colours and the ghost's.
LEGEND_BOX = ("background: rgb(51, 115, 204)", "box")
LEGEND_PLANNED = ("border: 2px solid rgb(26, 178, 51)", "planned box pose (outline)")
LEGEND_LINKS = ("background: rgb(89, 89, 102); height: 5px", "finger links")
LEGEND_SPACE_LINKS = ("background: rgb(102, 102, 115); height: 5px", "finger links")  # fingerpro4.sdf's grey


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
    """The simulated run's legend in the plane, naming the object by object_noun; with the arrows' scale,
    their entry (for `num_fingers` fingers)."""
    return run_legend(object_noun(config), "outline", newtons_per_cm, num_fingers)


def run_legend(
    noun: str, ghost: str, newtons_per_cm: float | None = None, num_fingers: int = 0, links=LEGEND_LINKS
) -> tuple:
    """A simulated run's legend: the object (`noun`), its planned pose drawn as `ghost` ("outline", "edges"),
    the finger `links` (CSS swatch, text) and, with the arrows' scale, their entry (for `num_fingers` fingers)."""
    entries = [(LEGEND_BOX[0], noun), (LEGEND_PLANNED[0], f"planned {noun} pose ({ghost})"), links]
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


def space_finger_labels(scene, *, offset: float = 0.03):
    """(text, CSS colour, x, y, z) of each finger's number of a hand in space (scene.spatial.SpaceScene), `offset`
    m outside its first joint (horizontally, away from the vertical through W's origin: the grasp point)."""
    labels = []
    for i, finger in enumerate(scene.fingers):
        base = np.asarray(finger.p_W_joint[0], dtype=float)
        out = np.array([base[0], base[1], 0.0]) / max(float(np.hypot(base[0], base[1])), 1e-9)
        x, y, z = base + offset * out
        labels.append((str(i), finger_css(i), float(x), float(y), float(z)))
    return labels


PAGE_SCRIPT = """
(function () {
  const HALF = %(half)s, DROP = %(drop)s, NOUN = %(noun)s;  // m, half-width of the view; s, drop time or null
  const LABELS = %(labels)s;  // [text, CSS colour, x m, y m(, z m)]: the finger numbers, at their bases in W
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
      const v = root.localToWorld(new MeshCat.THREE.Vector3(label[2], label[3], label[4] || 0)).project(c);
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
    (finger_labels) or (text, CSS colour, x, y, z) in space (space_finger_labels), and an orthographic (planar)
    view kept centred in any window shape."""
    drop = "null" if drop_time_s is None else f"{float(drop_time_s):.6f}"
    marker = "" if drop_time_s is None else '<div id="tt-drop"></div>'
    note = "" if drop_time_s is None else '<div id="tt-drop-note"></div>'
    items = fingers_line(len(labels)) + "".join(
        f'<div><span class="tt-swatch" style="{escape(style)}"></span>{escape(text)}</div>' for style, text in legend
    )
    marks = "".join(
        f'<div class="tt-label" id="tt-label-{k}" style="color: {escape(color)}">{escape(text)}</div>'
        for k, (text, color, *_) in enumerate(labels)
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
