"""A run as a matplotlib GIF for places without WebGL: the object and hand on x, y axes (in space: on 3D axes,
trajectotree.figures.space), each fingertip in its finger's colour and each finger's force on the object as an
arrow, at one scale per run that the GIF states. matplotlib is imported only when a GIF is written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from trajectotree.execution.meshcat_scene import VIEW_HALF_WIDTH
from trajectotree.execution.playback_page import object_noun
from trajectotree.figures.legend import arrow_newtons_per_cm, arrow_scale_text

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
    finger's force on the object (`forces` (T, F, 2)) as an arrow at `newtons_per_cm` (default:
    arrow_newtons_per_cm of the forces), the time of each frame and a `title` above it. A run in space
    (`scene` a scene.spatial.SpaceScene, poses (T, 7), forces (T, F, 3)) on 3D axes in one view of the plan
    (figures.space.plot_space_frame), the planned cube's edges dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import PillowWriter

    from trajectotree.figures.run import plot_run_frame
    from trajectotree.figures.space import plot_space_frame, view_bounds

    times = np.asarray(times)
    frames = np.unique(np.searchsorted(times, np.arange(times[0], times[-1] + 1e-9, 1.0 / fps)).clip(0, len(times) - 1))
    if forces is not None and newtons_per_cm is None:
        newtons_per_cm = arrow_newtons_per_cm(forces)
    space = np.shape(object_poses)[-1] == 7  # [qw, qx, qy, qz, px, py, pz]: a run in space
    noun = "cube" if space else object_noun(scene.config)
    notes = ([f"dashed: planned {noun} pose"] if planned_poses is not None else []) + (
        [f"arrows: each finger's force on the {noun}, {arrow_scale_text(newtons_per_cm)}"] if forces is not None else []
    )
    fig, ax = plt.subplots(figsize=(4.6, 4.6 + 0.18 * len(notes)), subplot_kw={"projection": "3d"} if space else {})
    if space:  # one view for every frame, of the plan (a dropped cube falls out of it)
        centre, half = view_bounds(scene, object_poses[:1] if planned_poses is None else planned_poses, joint_angles)

    def draw(k):
        ax.clear()
        clock = f"t = {times[k]:.2f} s of {times[-1]:.2f} s"
        common = dict(
            planned_pose=None if planned_poses is None else planned_poses[k],
            forces=None if forces is None else forces[k],
            newtons_per_cm=newtons_per_cm,
            title=f"{title}\n{clock}" if title else clock,
        )
        if space:
            plot_space_frame(ax, scene, object_poses[k], joint_angles[k], centre=centre, half=half, **common)
        else:
            plot_run_frame(ax, scene, object_poses[k], joint_angles[k], half_width=VIEW_HALF_WIDTH, **common)

    if notes:
        fig.text(0.5, 0.01, "\n".join(notes), ha="center", va="bottom", fontsize=7.5, color="0.25")
    draw(frames[0])
    fig.tight_layout(rect=(0, 0.045 * len(notes), 1, 1))
    fig.set_layout_engine(None)  # the layout is fixed: tight_layout's placeholder engine made each savefig draw twice
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    writer = PillowWriter(fps=fps)
    try:
        # Each frame drawn once, by the writer's savefig (FuncAnimation drew it three times).
        with writer.saving(fig, tmp, GIF_DPI):
            for k in frames:
                draw(k)
                writer.grab_frame()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
        plt.close(fig)
