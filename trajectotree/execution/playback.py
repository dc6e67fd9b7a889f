"""Playing given poses back without physics: the plan's trajectory (object, hand and each finger's
planned force on the object) recorded into a self-contained Meshcat HTML page, in the plane and in space.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import Config
from trajectotree.execution.force_arrows import add_force_arrows, set_force_arrows
from trajectotree.execution.meshcat_scene import (
    PUBLISH_PERIOD,
    add_space_visualizer,
    add_visualizer,
    set_planar_view,
    start_meshcat,
)
from trajectotree.execution.playback_page import (
    LEGEND_BOX,
    LEGEND_LINKS,
    LEGEND_SPACE_LINKS,
    arrows_legend,
    finger_labels,
    object_noun,
    save_recording_html,
    space_finger_labels,
)
from trajectotree.figures.legend import arrow_newtons_per_cm
from trajectotree.scene.hand import hand_file, read_hand
from trajectotree.scene.plant import add_hand_and_box


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


def write_space_plan_html(scene, arrays: dict, path: str | Path, *, title: str, meshcat: Meshcat | None = None) -> None:
    """Plays a plan in space (its arrays, results.SPACE_TRAJECTORY_ARRAYS) of the hand and cube of `scene`
    (scene.spatial.SpaceScene, whose hand description and object a plant of its own is built from) in a
    self-contained HTML file at `path`: each knot published at its time, each finger's planned force on the cube
    as an arrow at the plan's scale."""
    from pydrake.multibody.parsing import Parser

    from trajectotree.scene.spatial import add_space_object

    meshcat = meshcat or start_meshcat()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    (hand,) = Parser(plant).AddModels(scene.hand_file.model)
    box = add_space_object(plant, scene.object)
    plant.Finalize()
    visualizer = add_space_visualizer(builder, plant, scene_graph, hand, box, scene.hand_file, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    f_W, tips = np.asarray(arrays["f_W"], dtype=float), np.asarray(arrays["p_W_tip"], dtype=float)
    newtons_per_cm = arrow_newtons_per_cm(f_W)
    add_force_arrows(meshcat, scene.num_fingers, dimensions=3)
    visualizer.StartRecording(set_transforms_while_recording=False)
    for k, t in enumerate(np.asarray(arrays["t"], dtype=float)):
        context.SetTime(t)
        plant.SetPositions(plant_context, box, np.asarray(arrays["x"][k], dtype=float))
        plant.SetPositions(plant_context, hand, np.asarray(arrays["q"][k], dtype=float))
        diagram.ForcedPublish(context)
        set_force_arrows(meshcat, tips[k], f_W[k], scene.tip_radius, newtons_per_cm, t)
    legend = (
        (LEGEND_BOX[0], "cube (planned pose)"),
        LEGEND_SPACE_LINKS,
        arrows_legend(newtons_per_cm, "planned", scene.num_fingers, "cube"),
    )
    save_recording_html(
        meshcat, visualizer, path, title=title, legend=legend, noun="cube", labels=space_finger_labels(scene)
    )
