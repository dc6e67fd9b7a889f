"""Watching a plan in space: its planned trajectory recorded into a self-contained Meshcat HTML file (the hand in
space and its cube, each fingertip in its finger's colour as in the plane, each finger's planned force on the
cube as a shaft in that colour at one scale per plan), without physics: each knot is published at its time.
"""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Box,
    IllustrationProperties,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.execution.meshcat_scene import PUBLISH_PERIOD, finger_css, start_meshcat
from trajectotree.figures.legend import (
    ARROW_MAX_LENGTH,
    ARROW_MIN_FORCE,
    arrow_newtons_per_cm,
    arrow_scale_text,
    finger_rgb,
)
from trajectotree.io import write_bytes_atomic
from trajectotree.scene.spatial import add_space_object

FORCE_PATH = "/forces"
SHAFT_RADIUS = 0.002  # m, half the shaft's width
CUBE_ALPHA = 0.45  # the cube's opacity in the playback
CAMERA_POSITION = (0.2, -0.2, 0.16)  # m, looking at the cube at the grasp point from the front right, above


def _color_fingertips(plant, scene_graph, hand, hand_file) -> None:
    """Each fingertip's sphere visual (on its tip frame's body, centred on the frame) in its finger's colour."""
    inspector = scene_graph.model_inspector()
    for i, finger in enumerate(hand_file.fingers):
        frame = plant.GetFrameByName(finger.tip, hand)
        X_BT = frame.GetFixedPoseInBodyFrame().translation()
        for g in plant.GetVisualGeometriesForBody(frame.body()):
            offset = inspector.GetPoseInFrame(g).translation() - X_BT
            if isinstance(inspector.GetShape(g), Sphere) and np.linalg.norm(offset) < 1e-9:
                properties = IllustrationProperties(inspector.GetIllustrationProperties(g))
                properties.UpdateProperty("phong", "diffuse", Rgba(*finger_rgb(i), 1.0))
                scene_graph.RemoveRole(plant.get_source_id(), g, Role.kIllustration)
                scene_graph.AssignRole(plant.get_source_id(), g, properties)


def _see_through(plant, scene_graph, instance) -> None:
    """The cube's visuals at CUBE_ALPHA: the force shafts run from the fingertips into it."""
    inspector = scene_graph.model_inspector()
    for body in plant.GetBodyIndices(instance):
        for g in plant.GetVisualGeometriesForBody(plant.get_body(body)):
            properties = IllustrationProperties(inspector.GetIllustrationProperties(g))
            rgba = properties.GetPropertyOrDefault("phong", "diffuse", Rgba(0.2, 0.45, 0.8, 1.0))
            properties.UpdateProperty("phong", "diffuse", Rgba(rgba.r(), rgba.g(), rgba.b(), CUBE_ALPHA))
            scene_graph.RemoveRole(plant.get_source_id(), g, Role.kIllustration)
            scene_graph.AssignRole(plant.get_source_id(), g, properties)


def _set_shaft(meshcat, i: int, tip, f, tip_radius: float, newtons_per_cm: float, time: float) -> None:
    """Finger i's shaft along its force f (3,) on the cube from its fingertip sphere's surface, |f| /
    newtons_per_cm cm long (at most ARROW_MAX_LENGTH, as the planar arrows), hidden below ARROW_MIN_FORCE."""
    path = f"{FORCE_PATH}/finger{i}"
    magnitude = float(np.linalg.norm(f))
    if magnitude < ARROW_MIN_FORCE:
        meshcat.SetProperty(path, "visible", False, time)
        return
    u = np.asarray(f) / magnitude
    length = min(magnitude / newtons_per_cm / 100, ARROW_MAX_LENGTH)
    R = RotationMatrix(np.column_stack(_frame(u)))  # the shaft along its frame's z: z along u
    centre = np.asarray(tip) + (tip_radius + length / 2) * u
    meshcat.SetTransform(path, RigidTransform(R, centre), time)
    meshcat.SetProperty(f"{path}/<object>", "scale", [1.0, 1.0, length], time)
    meshcat.SetProperty(path, "visible", True, time)


def _frame(u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal columns (x, y, z = u) of a frame whose z is the unit vector u."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, u)
    x /= np.linalg.norm(x)
    return x, np.cross(u, x), np.asarray(u, dtype=float)


def write_space_plan_html(scene, arrays: dict, path: str | Path, *, title: str) -> None:
    """Plays a plan in space (its arrays, results.SPACE_TRAJECTORY_ARRAYS) of the hand and cube of `scene`
    (scene.spatial.SpaceScene, whose hand description, object and gravity a plant of its own is built from, with
    a visualizer) in a self-contained HTML file at `path`."""
    hand_file = scene.hand_file
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    (model,) = Parser(plant).AddModels(hand_file.model)
    instance = add_space_object(plant, scene.object)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -scene.gravity])
    plant.Finalize()
    _color_fingertips(plant, scene_graph, model, hand_file)
    _see_through(plant, scene_graph, instance)
    meshcat = start_meshcat()
    visualizer = MeshcatVisualizer.AddToBuilder(
        builder, scene_graph, meshcat, MeshcatVisualizerParams(publish_period=PUBLISH_PERIOD)
    )
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    meshcat.SetCameraPose(np.array(CAMERA_POSITION), np.zeros(3))
    F = len(hand_file.fingers)
    for i in range(F):
        # a box, not a cylinder: Meshcat's cylinder turns its y-up geometry inside the object, so a scale along z
        # would stretch its radius; a box's axes are Drake's (the planar arrows scale one so too)
        shaft = Box(2 * SHAFT_RADIUS, 2 * SHAFT_RADIUS, 1.0)
        meshcat.SetObject(f"{FORCE_PATH}/finger{i}", shaft, Rgba(*finger_rgb(i), 1.0))
    f_W, tips = np.asarray(arrays["f_W"]), np.asarray(arrays["p_W_tip"])
    newtons_per_cm = arrow_newtons_per_cm(f_W.reshape(-1, 3))
    tip_radius = scene.tip_radius
    visualizer.StartRecording(set_transforms_while_recording=False)
    for k, t in enumerate(np.asarray(arrays["t"], dtype=float)):
        context.SetTime(t)
        plant.SetPositions(plant_context, instance, np.asarray(arrays["x"][k], dtype=float))
        plant.SetPositions(plant_context, model, np.asarray(arrays["q"][k], dtype=float))
        diagram.ForcedPublish(context)
        for i in range(F):
            _set_shaft(meshcat, i, tips[k, i], f_W[k, i], tip_radius, newtons_per_cm, t)
    visualizer.StopRecording()
    visualizer.PublishRecording()
    write_bytes_atomic(path, _decorated(meshcat.StaticHtml(), title, F, newtons_per_cm).encode())


def _decorated(html: str, title: str, num_fingers: int, newtons_per_cm: float) -> str:
    """Meshcat's page with `title` (tab and overlay) and a legend: each fingertip's colour and the shafts' scale."""
    dots = "".join(
        f'<span style="display:inline-block;width:10px;height:10px;border-radius:5px;margin:0 3px 0 8px;'
        f'background:{finger_css(i)}"></span>{i}'
        for i in range(num_fingers)
    )
    overlay = (
        '<div style="position:fixed;left:10px;top:8px;font:14px sans-serif;background:rgba(255,255,255,0.8);'
        f'padding:4px 8px;z-index:10"><b>{escape(title)}</b><br>fingertips{dots}<br>'
        f"shaft: planned force of each finger on the cube, {escape(arrow_scale_text(newtons_per_cm))}</div>"
    )
    start, end = html.find("<title>"), html.find("</title>")
    if start >= 0 and end > start:
        html = html[:start] + f"<title>{escape(title)}</title>" + html[end + len("</title>") :]
    body_end = html.rfind("</body>")
    return html[:body_end] + overlay + html[body_end:] if body_end >= 0 else html + overlay
