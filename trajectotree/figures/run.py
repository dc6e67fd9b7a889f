"""Figures of one plan or one run: the box, the hand, a contact plan's keyframes (the
paper's Fig. 1) and each finger's force on the box over one execution. The plot_*
functions draw on a given matplotlib `ax` and return their artists; the figure_*
functions assemble a figure and return it; save_figure writes one.

The execution side (playback, the simulate and demo commands) draws with this module;
the sweep's statistics (box plots, confidence bands) are in trajectotree.figures.statistics and
their figures in trajectotree.experiments.report.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from matplotlib.patches import Circle, Polygon

from trajectotree.config import DEFAULT_HAND
from trajectotree.figures.legend import (  # noqa: F401 (the figures' users read them here too)
    ARROW_MAX_LENGTH,
    ARROW_MIN_FORCE,
    ARROW_TARGET_LENGTH,
    FINGER_COLORS,
    arrow_newtons_per_cm,
    arrow_scale_text,
    controller_text,
    force_arrow,
)
from trajectotree.geometry import ConvexPolygon, box_to_world
from trajectotree.io import write_bytes_atomic


def plot_force_arrows(ax, tips, forces, tip_radius: float, newtons_per_cm: float, *, colors=FINGER_COLORS):
    """Each finger's force on the object (forces (4, 2), fingertip centres tips (4, 2)) as an
    arrow in its colour (force_arrow), drawn above the object."""
    from matplotlib.patches import FancyArrow

    artists = []
    for i, (tip, f) in enumerate(zip(tips, forces)):
        arrow = force_arrow(tip, f, tip_radius, newtons_per_cm)
        if arrow is None:
            continue
        start, end = arrow
        head = min(0.012, float(np.hypot(*(end - start))) / 2)  # m: a short arrow's head takes half of it
        artists.append(
            ax.add_patch(
                FancyArrow(
                    *start,
                    *(end - start),
                    width=0.004,
                    head_width=head,
                    head_length=head,
                    length_includes_head=True,
                    color=colors[i],
                    ec="k",
                    lw=0.4,
                    zorder=8,
                )
            )
        )
    return artists


def plot_finger_numbers(ax, scene, *, colors=FINGER_COLORS, fontsize=7):
    """Each finger's number at its base in its colour, below a base in the lower half, above the others."""
    return [
        ax.annotate(
            str(i),
            finger.p_W_base,
            xytext=(0, -10 if finger.p_W_base[1] < 0 else 4),
            textcoords="offset points",
            ha="center",
            fontsize=fontsize,
            color=colors[i],
            fontweight="bold",
        )
        for i, finger in enumerate(scene.fingers)
    ]


def plot_object(ax, shape: ConvexPolygon, pose, *, color="tab:blue", alpha=0.35, **kwargs):
    """The object's outline `shape` (a ConvexPolygon in B) at object pose (x, y, theta)."""
    corners = np.array([box_to_world(pose, c) for c in shape.vertices])
    return [ax.add_patch(Polygon(corners, closed=True, facecolor=color, edgecolor="k", alpha=alpha, **kwargs))]


def plot_box(ax, width: float, height: float, pose, **kwargs):
    """The width x height box at object pose (x, y, theta) (plot_object)."""
    return plot_object(ax, ConvexPolygon.box(width, height), pose, **kwargs)


def plot_reachable_contacts(ax, shape: ConvexPolygon, pose, arclengths, *, colors=FINGER_COLORS, step=0.004):
    """Each finger's reachable contacts (arclengths, one array per finger) as dots in its colour,
    finger i's row 0.004 (i + 1) m outside the boundary so that the four rows stay apart."""
    artists = []
    for i, s in enumerate(arclengths):
        if len(s) == 0:
            continue
        p_B, n_B = shape.points(np.asarray(s, dtype=float))
        p_W = np.array([box_to_world(pose, p) for p in p_B + step * (i + 1) * n_B])
        artists.append(ax.scatter(p_W[:, 0], p_W[:, 1], s=5, color=colors[i], zorder=6))
    return artists


def plot_finger(ax, finger, q, tip_radius: float, *, color="0.3", tip_color="tab:red", lw=3.0):
    """One two-link finger (a FingerGeometry) at joint angles q (2,)."""
    a1 = finger.psi + q[0]
    elbow = finger.p_W_base + finger.l1 * np.array([np.cos(a1), np.sin(a1)])
    tip = finger.fingertip(q)
    pts = np.array([finger.p_W_base, elbow, tip])
    artists = ax.plot(pts[:, 0], pts[:, 1], "-", color=color, lw=lw, solid_capstyle="round", zorder=3)
    artists += ax.plot(pts[:2, 0], pts[:2, 1], "o", color="k", ms=3, zorder=4)
    artists.append(ax.add_patch(Circle(tip, tip_radius, color=tip_color, zorder=5)))
    return artists


def plot_hand(ax, scene, q, *, colors=FINGER_COLORS, **kwargs):
    """All fingers of `scene` at joint angles q (2F,)."""
    artists = []
    for i, finger in enumerate(scene.fingers):
        artists += plot_finger(ax, finger, q[2 * i : 2 * i + 2], scene.tip_radius, tip_color=colors[i], **kwargs)
    return artists


def plot_workspace(ax, finger, *, color="0.6"):
    """Outer reach circle of one finger around its base (dashed)."""
    return [ax.add_patch(Circle(finger.p_W_base, finger.l1 + finger.l2, fill=False, ls="--", color=color, lw=0.8))]


def plot_run_frame(
    ax, scene, pose, q, *, half_width: float, planned_pose=None, forces=None, newtons_per_cm=1.0, title=None
):
    """One frame of a run (the GIF's): the object at `pose`, the hand at joint angles q with the
    fingers numbered, the planned pose as a dashed outline, each finger's force on the object
    (forces (4, 2)) as an arrow at newtons_per_cm (plot_force_arrows), on x, y axes in m over
    [-half_width, half_width]^2, titled `title`."""
    ax.set_aspect("equal")
    ax.set_xlim(-half_width, half_width)
    ax.set_ylim(-half_width, half_width)
    ax.set_xlabel("x [m]", fontsize=9)
    ax.set_ylabel("y [m]", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(color="0.92", lw=0.5)
    ax.set_axisbelow(True)
    shape = scene.config.shape
    artists = [] if planned_pose is None else plot_object(ax, shape, planned_pose, color="none", alpha=1.0, ls="--")
    artists += plot_object(ax, shape, pose)
    artists += plot_hand(ax, scene, q)
    artists += plot_finger_numbers(ax, scene, fontsize=9)
    if forces is not None:
        artists += plot_force_arrows(ax, scene.fingertip_positions(q), forces, scene.tip_radius, newtons_per_cm)
    if title:
        artists.append(ax.set_title(title, fontsize=9))
    return artists


def figure_model(scene, q=None, reachable=None, note: str | None = None):
    """The hand at joint angles q (default: a fixed open pose) with each finger's reach dashed,
    the object at its initial pose, gravity, and optionally each finger's reachable contacts
    (`reachable`: arclengths per finger, plot_reachable_contacts) and a `note` below the title."""
    import matplotlib.pyplot as plt

    from trajectotree.scene.plant import describe_object

    fig, ax = plt.subplots(figsize=(5, 5))
    c = scene.config
    plot_object(ax, c.shape, c.initial_pose)
    for f in scene.fingers:
        plot_workspace(ax, f)
    if reachable is not None:
        plot_reachable_contacts(ax, c.shape, c.initial_pose, reachable)
    plot_hand(ax, scene, np.tile([0.25, 1.2], 4) if q is None else q)
    for i, f in enumerate(scene.fingers):
        ax.annotate(f"finger {i}", f.p_W_base, textcoords="offset points", xytext=(0, 8), ha="center", fontsize=8)
    ax.annotate("", xy=(0.0, -0.27), xytext=(0.0, -0.2), arrowprops={"arrowstyle": "->"})
    ax.text(0.005, -0.24, "g", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlim(-0.3, 0.3)
    ax.set_ylim(-0.3, 0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    hand = (
        "Planar four-finger hand"
        if c.hand == DEFAULT_HAND
        else f"Hand {scene.hand_description.name} ({scene.num_fingers} fingers)"
    )
    ax.set_title(f"{hand} and {describe_object(c)}" + (f"\n{note}" if note else ""), fontsize=10)
    fig.tight_layout()
    return fig


def plot_finger_force(ax, t, f_sim, f_plan, *, color=None, drop_time=None):
    """Magnitudes |f| of one finger's simulated (solid) and planned (dashed) force on the
    box over time; f_sim, f_plan (T, 2) or (T, 3). After a drop, if any, the time is shaded grey."""
    (sim,) = ax.plot(t, np.linalg.norm(f_sim, axis=1), color=color, lw=1.2, label="simulated |f|")
    (plan,) = ax.plot(t, np.linalg.norm(f_plan, axis=1), color=sim.get_color(), lw=1.2, ls="--", label="planned |f|")
    artists = [sim, plan]
    if drop_time is not None:
        artists.append(
            ax.axvspan(drop_time, t[-1], color="0.85", zorder=0, lw=0, label="after the drop (may be clipped)")
        )
    return artists


def plot_segments(ax, spans, finger: int | None = None, *, color="gold"):
    """Segment boundaries (dotted) of spans [(t_start, t_end, switching finger or None)];
    the segments in which `finger` switches are shaded."""
    artists = [ax.axvline(t0, color="0.5", ls=":", lw=0.8, zorder=0) for t0, _, _ in spans[1:]]
    for t0, t1, switching in spans:
        if finger is not None and switching == finger:
            artists.append(
                ax.axvspan(
                    t0, t1, color=color, alpha=0.25, lw=0, zorder=0, label="segment in which this finger switches"
                )
            )
    return artists


def slip_intervals(t, slipping) -> list[tuple[float, float]]:
    """(start, end) of each run of samples where `slipping` (T,) holds; a run ends at the next
    sample's time (the last sample's own time at the end)."""
    slipping = np.asarray(slipping, dtype=bool)
    edges = np.flatnonzero(np.diff(np.r_[0, slipping.astype(int), 0]))
    ends = np.minimum(edges[1::2], len(t) - 1)
    return [(float(t[a]), float(t[b])) for a, b in zip(edges[0::2], ends)]


def plot_slip_intervals(ax, t, slipping, *, color="crimson"):
    """One finger's slip intervals (a closed-loop run's ClosedLoopLog.slipping[:, i]) as
    hatched spans."""
    return [
        ax.axvspan(a, b, facecolor="none", edgecolor=color, alpha=0.4, hatch="//", lw=0, zorder=0, label="slipping")
        for a, b in slip_intervals(t, slipping)
    ]


def plot_contacts(ax, pose, p_BC, n_B, *, colors=FINGER_COLORS, size=18):
    """Contact points p_BC (k, 2) of the box at `pose`, one colour per finger, with their
    outward normals n_B as short arrows."""
    p_W = np.array([box_to_world(pose, p) for p in p_BC])
    n_W = np.array([box_to_world((0.0, 0.0, pose[2]), n) for n in n_B])
    artists = [ax.scatter(p_W[:, 0], p_W[:, 1], s=size, c=list(colors[: len(p_W)]), edgecolors="k", zorder=6)]
    artists.append(
        ax.quiver(
            p_W[:, 0],
            p_W[:, 1],
            n_W[:, 0],
            n_W[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1 / 0.02,
            width=0.004,
            color="k",
            zorder=6,
        )
    )
    return artists


def plot_friction_cones(ax, pose, p_BC, n_B, mu: float, *, length=0.03, color="tab:cyan", alpha=0.4):
    """The friction cone of each contact: the forces a finger can apply on the box,
    -n + [-mu, mu] t, drawn as a wedge from the contact point into the box."""
    artists = []
    for p, n in zip(p_BC, n_B):
        t = np.array([-n[1], n[0]])
        edges = [(-n + sign * mu * t) / np.hypot(1.0, mu) for sign in (-1.0, 1.0)]
        wedge = [box_to_world(pose, p)] + [box_to_world(pose, p + length * e) for e in edges]
        artists.append(
            ax.add_patch(Polygon(np.array(wedge), closed=True, facecolor=color, edgecolor=color, alpha=alpha, zorder=5))
        )
    return artists


def plot_contact_node(ax, scene, node, *, mu: float, previous=None):
    """One node of a contact plan (a ContactNode) like the paper's Fig. 1 keyframes: box,
    hand at the node's joint angles, contacts with friction cones; the switching finger is
    drawn thick, with its previous contact (from `previous`, a ContactNode) as a hollow marker."""
    c = scene.config
    artists = plot_object(ax, c.shape, node.object_pose)
    for i, finger in enumerate(scene.fingers):
        switching = i == node.switching_finger
        artists += plot_finger(
            ax,
            finger,
            node.q[2 * i : 2 * i + 2],
            scene.tip_radius,
            color="k" if switching else "0.55",
            lw=4.0 if switching else 2.0,
            tip_color=FINGER_COLORS[i],
        )
    artists += plot_finger_numbers(ax, scene)
    artists += plot_friction_cones(ax, node.object_pose, node.p_BC, node.n_B, mu)
    artists += plot_contacts(ax, node.object_pose, node.p_BC, node.n_B)
    if previous is not None and node.switching_finger is not None:
        p_W = box_to_world(node.object_pose, previous.p_BC[node.switching_finger])
        artists += ax.plot(*p_W, "o", mfc="none", mec=FINGER_COLORS[node.switching_finger], ms=7, mew=1.5, zorder=7)
    return artists


def contact_node_legend_handles(mu: float):
    """Legend entries of plot_contact_node's marks (proxy artists)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    return [
        Line2D(
            [], [], marker="o", ls="none", mfc="0.6", mec="k", ms=6, label="contact (finger's colour; arrow: normal)"
        ),
        Patch(facecolor="tab:cyan", alpha=0.4, label=f"friction cone (mu = {mu:.2g})"),
        Line2D(
            [],
            [],
            marker="o",
            ls="none",
            mfc="none",
            mec="0.3",
            ms=7,
            mew=1.5,
            label="switching finger's previous contact",
        ),
        Line2D([], [], color="k", lw=4.0, label="switching finger"),
        Line2D([], [], color="0.55", lw=2.0, label="holding fingers (numbered at their bases)"),
    ]


KEYFRAME_HALF_WIDTH = 0.26  # m, each keyframe panel shows [-0.26, 0.26]^2
KEYFRAME_TICKS = (-0.2, -0.1, 0.0, 0.1, 0.2)  # m


def angle_text(theta: float) -> str:
    """An angle in rad and in degrees, e.g. "+0.17 rad (+10.0°)"."""
    return f"{theta:+.2f} rad ({math.degrees(theta):+.1f}°)"


def figure_keyframes(scene, plan):
    """A contact plan (ContactPlan) as keyframes like the paper's Fig. 1: one panel per node
    (plot_contact_node) on the same x, y axes in m (labelled on the outer panels, a light grid
    as the scale), each titled with the node's theta in rad and degrees; the legend below. The
    cones are the plan's (mu_plan, the friction the search planned with; scene.mu for a plan
    that does not record it)."""
    import matplotlib.pyplot as plt

    mu = plan.mu_plan if math.isfinite(plan.mu_plan) else scene.config.mu
    cols = min(5, len(plan.nodes))
    rows = math.ceil(len(plan.nodes) / cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(max(2.6 * cols, 7.0) + 0.5, 3.1 * rows + 1.0), squeeze=False, sharex=True, sharey=True
    )
    for n, ax in enumerate(axes.flat):
        if n >= len(plan.nodes):
            ax.set_axis_off()
            continue
        node = plan.nodes[n]
        plot_contact_node(ax, scene, node, mu=mu, previous=plan.nodes[n - 1] if n else None)
        ax.set_aspect("equal")
        ax.set_xlim(-KEYFRAME_HALF_WIDTH, KEYFRAME_HALF_WIDTH)
        ax.set_ylim(-KEYFRAME_HALF_WIDTH, KEYFRAME_HALF_WIDTH)
        ax.set_xticks(KEYFRAME_TICKS)
        ax.set_yticks(KEYFRAME_TICKS)
        below = n + cols < len(plan.nodes)  # another panel under this one carries the x labels
        ax.tick_params(labelsize=7, length=2, pad=1, labelbottom=not below, labelleft=n % cols == 0)
        ax.grid(color="0.92", lw=0.5, zorder=0)
        ax.set_axisbelow(True)
        for spine in ax.spines.values():
            spine.set_color("0.7")
        if n % cols == 0:
            ax.set_ylabel("y [m]", fontsize=8, labelpad=1)
        if not below:
            ax.set_xlabel("x [m]", fontsize=8, labelpad=1)
        moved = (
            "initial grasp"
            if n == 0
            else ("no switch" if node.switching_finger is None else f"finger {node.switching_finger} moves")
        )
        ax.set_title(f"n={n}  θ = {angle_text(node.object_pose[2])}\n{moved}", fontsize=8)
    fig.suptitle(
        f"contact sequence for goal θ = {plan.goal:+.3f} rad ({math.degrees(plan.goal):+.1f}°)"
        " (switching finger drawn thick)",
        fontsize=10,
    )
    handles = contact_node_legend_handles(mu)
    ncol = 3 if cols >= 4 else 2
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    height = fig.get_figheight()  # inches: the legend's rows below, the title above
    fig.tight_layout(rect=(0, (0.2 * math.ceil(len(handles) / ncol) + 0.1) / height, 1, 1 - 0.3 / height))
    return fig


def segment_spans(switching_fingers, knots_per_segment: int, dt: float) -> list[tuple[float, float, int | None]]:
    """(t_start, t_end, switching finger) of each transition segment of a plan whose nodes
    have `switching_fingers` (node 0 has none); a segment spans knots_per_segment steps of dt."""
    length = knots_per_segment * dt
    return [((n - 1) * length, n * length, finger) for n, finger in enumerate(switching_fingers) if n > 0]


def world_text(conditions: dict) -> str | None:
    """The simulated world where it differs from the plan's (a SimLog's conditions), e.g.
    "simulated mu 0.55 (plan 0.7), push (0.2, 0) N at 5.6 s"; None for the plan's world."""
    parts = []
    if conditions.get("sim_mu") is not None and conditions.get("sim_mu") != conditions.get("plan_mu"):
        parts.append(f"simulated mu {conditions['sim_mu']:g} (plan {conditions['plan_mu']:g})")
    if conditions.get("sim_mass") is not None and conditions.get("sim_mass") != conditions.get("plan_mass"):
        parts.append(f"mass {1e3 * conditions['sim_mass']:g} g (plan {1e3 * conditions['plan_mass']:g} g)")
    push = conditions.get("push")
    if push:
        force = ", ".join(f"{c:g}" for c in push["force"])
        parts.append(f"push ({force}) N at {push['time_s']:g} s for {push['duration_s']:g} s")
    return ", ".join(parts) or None


def goal_text(goal) -> str | None:
    """The goal as the figures state it: a planar rotation θ (a finite number) or a goal quaternion in space
    ([w, x, y, z], four finite numbers, with its angle); None for anything else (a plan.json's may be anything)."""
    if isinstance(goal, (int, float)) and not isinstance(goal, bool) and math.isfinite(goal):
        return f"goal θ = {goal:+.3f} rad ({math.degrees(goal):+.1f}°)"
    quaternion = np.asarray(goal, dtype=float) if isinstance(goal, (list, tuple, np.ndarray)) else np.zeros(0)
    if quaternion.shape != (4,) or not np.isfinite(quaternion).all() or np.linalg.norm(quaternion) == 0:
        return None
    angle = 2 * math.acos(min(abs(quaternion[0]) / np.linalg.norm(quaternion), 1.0))
    w, x, y, z = quaternion
    return f"goal quaternion [{w:+.3f}, {x:+.3f}, {y:+.3f}, {z:+.3f}] (a {math.degrees(angle):.1f}° turn)"


def forces_title(result, goal=None, noun: str = "box") -> str:
    """The forces figure's title: what it shows (the force on the `noun`), the goal (goal_text), the
    controller and any simulated world that differs from the plan's."""
    stated = goal_text(goal)
    run = ([stated] if stated else []) + [controller_text(result.controller)]
    world = world_text(result.conditions)
    return f"force of each finger on the {noun}, magnitude |f|\n" + ", ".join(run) + (f"; {world}" if world else "")


def figure_finger_forces(result, segments=None, goal=None, noun: str = "box"):
    """Each finger's simulated vs planned force magnitude |f| on the box (the `noun`) over one executed
    plan (a SimResult, or a SpaceSimResult: forces (T, F, 2) or (T, F, 3)), on one shared scale: where
    the run leaves the plan's contact forces, and when. `segments` (segment_spans) marks the segments and
    each finger's switches, and a closed-loop run's slip intervals are hatched; the title names the plan's
    `goal` (rad, or a quaternion in space), the controller and the simulated world (forces_title). The
    scale covers the plan and the run up to the drop: a fallen box squeezed between the fingers does not
    set it (clipped in the grey span)."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fingers = result.f_W.shape[1]
    fig, axes = plt.subplots(fingers, 1, figsize=(8, 1.6 * fingers + 1.1), sharex=True, sharey=True)
    height = fig.get_figheight()  # inches: the two-line title, then the legend's rows, then the panels
    held = result.t <= (result.drop_time_s if result.drop_time_s is not None else np.inf)
    top = max(np.linalg.norm(result.f_W_plan, axis=-1).max(), np.linalg.norm(result.f_W[held], axis=-1).max(), 0.1)
    for i, ax in enumerate(axes):
        plot_finger_force(
            ax, result.t, result.f_W[:, i], result.f_W_plan[:, i], color=FINGER_COLORS[i], drop_time=result.drop_time_s
        )
        if segments:
            plot_segments(ax, segments, i)
        watch = getattr(result, "closed_loop", None)  # what a closed-loop run's contact watch saw
        if watch is not None:
            plot_slip_intervals(ax, result.t, watch.slipping[:, i])
        ax.set_ylabel(f"finger {i}\n|f| [N]")
        ax.grid(alpha=0.3)
        ax.set_ylim(-0.03 * top, 1.1 * top)
    handles = {}
    for ax in axes:  # one legend entry per label, from whichever panel has it
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    for label, style in (("simulated |f|", "-"), ("planned |f|", "--")):  # every finger's colour, one style
        handles[label] = Line2D([], [], color="k", ls=style, lw=1.2)
    if segments:
        handles["segment boundary"] = Line2D([], [], color="0.5", ls=":", lw=0.8)
    fig.legend(
        handles.values(),
        handles.keys(),
        fontsize=8,
        ncol=min(len(handles), 3),
        loc="upper center",
        bbox_to_anchor=(0.5, 1 - 0.5 / height),
        frameon=False,
    )
    fig.suptitle(forces_title(result, goal, noun), fontsize=10, y=1 - 0.05 / height)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout(rect=(0, 0, 1, 1 - (0.1 + 0.17 * math.ceil(len(handles) / 3)) / height))
    return fig


def save_figure(fig, path: str | Path, dpi: int = 150) -> str:
    """Writes fig to path atomically, in the format its suffix names (png by default)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format=Path(path).suffix.lstrip(".").lower() or "png", dpi=dpi)
    write_bytes_atomic(path, buffer.getvalue())
    return str(path)
