"""Playing given poses back without physics: the plan's trajectory (object, hand and each finger's
planned force on the object) recorded into a self-contained Meshcat HTML page.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import Config
from trajectotree.execution.force_arrows import add_force_arrows, set_force_arrows
from trajectotree.execution.meshcat_scene import PUBLISH_PERIOD, add_visualizer, set_planar_view, start_meshcat
from trajectotree.execution.playback_page import (
    LEGEND_BOX,
    LEGEND_LINKS,
    arrows_legend,
    finger_labels,
    object_noun,
    save_recording_html,
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
