"""Figures of a plan or a run in space: a contact sequence's keyframes (search.space_tree), one 3D view per
node, the fingers coloured as in the plane (figures.legend.FINGER_COLORS), the switching finger drawn thick; and
one frame of a run (the GIF's): the cube as simulated, the planned cube's edges dashed, each finger's force on
the cube as an arrow at the run's scale.
"""

from __future__ import annotations

import math

import numpy as np

from trajectotree.figures.legend import FINGER_COLORS, force_arrow
from trajectotree.geometry import quaternion_angle, quaternion_matrices

VIEW_ELEVATION, VIEW_AZIMUTH = 22.0, -58.0  # deg, one view for every panel: the mounts above, the cube below
VIEW_MARGIN = 0.04  # m around the box and the fingertips, enough to show each finger's last link leaving
CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
CUBE_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(CORNER_SIGNS[a] != CORNER_SIGNS[b]) == 1]
CUBE_FACES = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]


def box_corners_W(half, pose) -> np.ndarray:
    """(8, 3) m: the corners in W of the box of half-sizes `half` at `pose` [qw, qx, qy, qz, px, py, pz]."""
    R = quaternion_matrices(np.asarray(pose[:4], dtype=float))
    return np.asarray(pose[4:], dtype=float) + (CORNER_SIGNS * np.asarray(half, dtype=float)) @ R.T


def finger_polylines(scene, q) -> np.ndarray:
    """(F, n + 1, 3) m: each finger's joint points, base first, then its fingertip centre, at q (F, n)."""
    lines = []
    for finger, angles in zip(scene.fingers, np.asarray(q, dtype=float)):
        points, _, tip = finger.frames(angles)
        lines.append(np.vstack([points, tip[None]]))
    return np.array(lines)


def clip_segment(a, b, lo, hi):
    """The part (a', b') of the segment a -> b (3,) inside the axis-aligned box [lo, hi], or None (Liang-Barsky)."""
    t0, t1, d = 0.0, 1.0, b - a
    for axis in range(3):
        for p, q in ((-d[axis], a[axis] - lo[axis]), (d[axis], hi[axis] - a[axis])):
            if p == 0:
                if q < 0:
                    return None
                continue
            t = q / p
            if p < 0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
    return (a + t0 * d, a + t1 * d) if t0 <= t1 else None


def plot_space_state(ax, scene, pose, q, bounds, *, thick: int | None = None, colors=FINGER_COLORS) -> None:
    """The cube at `pose` (7,) on a 3D `ax` (faces translucent, edges grey) and the hand at q (F, n): each finger's
    links within `bounds` (lo, hi (3,) m: matplotlib does not clip 3D lines) and fingertip in its colour, finger
    `thick` drawn thick."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    corners = box_corners_W(scene.object.half, pose)
    ax.add_collection3d(
        Poly3DCollection([corners[f] for f in CUBE_FACES], facecolor="tab:blue", alpha=0.18, edgecolor="none")
    )
    for a, b in CUBE_EDGES:
        ax.plot(*corners[[a, b]].T, color="0.35", lw=0.8)
    lines = finger_polylines(scene, np.reshape(q, (scene.num_fingers, -1)))
    for i, line in enumerate(lines):
        for a, b in zip(line[:-1], line[1:]):
            part = clip_segment(a, b, *bounds)
            if part is not None:
                ax.plot(*np.array(part).T, color=colors[i], lw=3.2 if i == thick else 1.6, solid_capstyle="round")
        ax.scatter(*line[-1], color=colors[i], s=40 if i == thick else 22, depthshade=False)


def plot_space_node(ax, scene, node, bounds, *, colors=FINGER_COLORS) -> None:
    """One node on a 3D `ax`: the cube and the hand (plot_space_state, the switching finger thick), the contact
    points black."""
    plot_space_state(ax, scene, node.object_pose, node.q, bounds, thick=node.switching_finger, colors=colors)
    R = quaternion_matrices(np.asarray(node.object_pose[:4], dtype=float))
    contacts = np.asarray(node.object_pose[4:]) + np.asarray(node.p_BC) @ R.T
    ax.scatter(*contacts.T, color="k", s=6, depthshade=False)


def view_bounds(scene, poses, qs) -> tuple[np.ndarray, float]:
    """(centre (3,), half-width) m of one cubic view for every panel or frame: the cube at `poses` (K, 7) and
    the fingertips at `qs` (K, F n) with VIEW_MARGIN around them (the links are cut at its bounds)."""
    points = np.concatenate(
        [finger_polylines(scene, np.reshape(q, (scene.num_fingers, -1)))[:, -1] for q in qs]
        + [box_corners_W(scene.object.half, pose) for pose in poses]
    )
    centre = 0.5 * (points.min(0) + points.max(0))
    return centre, 0.5 * float(np.max(points.max(0) - points.min(0))) + VIEW_MARGIN


def set_view(ax, centre, half: float) -> None:
    """A 3D `ax` on the cube of half-width `half` m about `centre`, seen from VIEW_ELEVATION, VIEW_AZIMUTH."""
    for axis, c in zip("xyz", centre):
        getattr(ax, f"set_{axis}lim")(c - half, c + half)
    for pane in (ax.xaxis.pane, ax.yaxis.pane, ax.zaxis.pane):
        pane.set_alpha(0.3)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=VIEW_ELEVATION, azim=VIEW_AZIMUTH)
    ax.tick_params(labelsize=5, pad=0)


def plot_space_frame(
    ax, scene, pose, q, *, centre, half: float, planned_pose=None, forces=None, newtons_per_cm=1.0, title=None
) -> None:
    """One frame of a run in space (the GIF's) on a 3D `ax`: the cube at `pose` and the hand at q
    (plot_space_state), the planned cube's edges dashed green, each finger's force on the cube (forces (F, 3) N)
    as an arrow in its colour from its fingertip at `newtons_per_cm` (figures.legend.force_arrow), in the view
    about `centre` of half-width `half` m (view_bounds), titled `title`."""
    bounds = (np.asarray(centre) - half, np.asarray(centre) + half)
    plot_space_state(ax, scene, pose, q, bounds)
    if planned_pose is not None:
        corners = box_corners_W(scene.object.half, planned_pose)
        for a, b in CUBE_EDGES:
            ax.plot(*corners[[a, b]].T, color="tab:green", lw=0.9, ls="--")
    if forces is not None:
        tips = finger_polylines(scene, np.reshape(q, (scene.num_fingers, -1)))[:, -1]
        for i, (tip, f) in enumerate(zip(tips, forces)):
            arrow = force_arrow(tip, f, scene.tip_radius, newtons_per_cm)
            if arrow is not None:
                start, end = arrow
                ax.quiver(*start, *(end - start), color=FINGER_COLORS[i], lw=1.8, arrow_length_ratio=0.3)
    set_view(ax, centre, half)
    if title:
        ax.set_title(title, fontsize=9)


def figure_space_keyframes(scene, plan):
    """A contact plan in space (SpaceContactPlan) as keyframes: one 3D panel per node, all from the same view
    and bounds (m), each titled with the box's rotation from the first node and the finger that moved."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    nodes = plan.nodes
    cols = min(5, len(nodes))
    rows = math.ceil(len(nodes) / cols)
    fig = plt.figure(figsize=(3.0 * cols + 0.4, 3.3 * rows + 1.0))
    centre, half = view_bounds(scene, [n.object_pose for n in nodes], [n.q for n in nodes])
    bounds = (centre - half, centre + half)
    for k, node in enumerate(nodes):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        plot_space_node(ax, scene, node, bounds)
        set_view(ax, centre, half)
        angle = math.degrees(quaternion_angle(nodes[0].object_pose[:4], node.object_pose[:4]))
        moved = "initial grasp" if k == 0 else ("no switch" if node.switching_finger is None else
                                                 f"finger {node.switching_finger} moves")  # fmt: skip
        ax.set_title(f"n={k}  turned {angle:.1f}°\n{moved}", fontsize=8, pad=0)
    w, x, y, z = plan.goal
    fig.suptitle(
        f"contact sequence in space for goal quaternion [{w:+.3f}, {x:+.3f}, {y:+.3f}, {z:+.3f}] "
        "(switching finger drawn thick, contacts black)",
        fontsize=10,
    )
    handles = [Line2D([], [], color=FINGER_COLORS[i], lw=2, label=f"finger {i}") for i in range(scene.num_fingers)]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.06, top=0.9, wspace=0.05, hspace=0.25)
    return fig
