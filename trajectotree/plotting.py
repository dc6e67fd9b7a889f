"""Plot functions: each draws on a given matplotlib `ax` and returns its artists.
Figure assembly (subplots, saving) lives with the callers (report, CLI)."""

from __future__ import annotations

import numpy as np
from matplotlib.patches import Circle, Polygon

from trajectotree.geometry import box_to_world

FINGER_COLORS = ("tab:red", "tab:green", "tab:purple", "tab:orange")


def plot_box(ax, width: float, height: float, pose, *, color="tab:blue", alpha=0.35, **kwargs):
    """The box at object pose (x, y, theta)."""
    a, b = width / 2, height / 2
    corners = np.array([box_to_world(pose, c) for c in ((a, -b), (a, b), (-a, b), (-a, -b))])
    return [ax.add_patch(Polygon(corners, closed=True, facecolor=color, edgecolor="k", alpha=alpha, **kwargs))]


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
    """All four fingers of `scene` at joint angles q (8,)."""
    artists = []
    for i, finger in enumerate(scene.fingers):
        artists += plot_finger(ax, finger, q[2 * i:2 * i + 2], scene.tip_radius, tip_color=colors[i], **kwargs)
    return artists


def plot_workspace(ax, finger, *, color="0.6"):
    """Outer reach circle of one finger around its base (dashed)."""
    return [ax.add_patch(Circle(finger.p_W_base, finger.l1 + finger.l2, fill=False, ls="--", color=color, lw=0.8))]


def plot_boxes_with_means(ax, samples, labels, *, colors=None, mean_marker="x"):
    """Standard box plots (median, quartiles, 1.5 IQR whiskers, outliers) of each 1-D
    sample, with the sample means marked by crosses (the paper's Fig. 2). An empty
    sample's slot says "no data"; with no data at all the value axis has no ticks."""
    samples = [np.asarray(s, dtype=float) for s in samples]
    positions = np.arange(1, len(samples) + 1)
    parts = ax.boxplot(samples, positions=positions, tick_labels=labels, patch_artist=True, widths=0.5,
                       medianprops={"color": "k"}, flierprops={"marker": ".", "markersize": 4})
    for patch, color in zip(parts["boxes"], colors or ()):
        patch.set_facecolor(color)
        patch.set_alpha(0.5)
    filled = [(p, s.mean()) for p, s in zip(positions, samples) if s.size]
    means = ax.plot([p for p, _ in filled], [m for _, m in filled], mean_marker, color="k", ms=8, mew=2,
                    ls="none", label="mean", zorder=5)
    empty = [ax.text(p, 0.5, "no data", transform=ax.get_xaxis_transform(), ha="center", va="center",
                     color="0.45", fontsize=9) for p, s in zip(positions, samples) if not s.size]
    if not filled:
        ax.set_yticks([])  # matplotlib's default -0.05..0.05 would read as values
    return [artist for group in parts.values() for artist in group] + means + empty


def plot_mean_band(ax, t, mean, lower, upper, *, color=None, label=None, alpha=0.25):
    """A mean curve over t with a shaded band between lower and upper (e.g. a 95%
    confidence interval, the paper's Fig. 3)."""
    (line,) = ax.plot(t, mean, color=color, label=label, lw=1.5)
    band = ax.fill_between(t, lower, upper, color=line.get_color(), alpha=alpha, lw=0)
    return [line, band]


def plot_finger_force(ax, t, f_sim, f_plan, *, color=None, drop_time=None):
    """Magnitudes |f| of one finger's simulated (solid) and planned (dashed) force on the
    box over time; f_sim, f_plan (T, 2). After a drop, if any, the time is shaded grey."""
    (sim,) = ax.plot(t, np.linalg.norm(f_sim, axis=1), color=color, lw=1.2, label="simulated |f|")
    (plan,) = ax.plot(t, np.linalg.norm(f_plan, axis=1), color=sim.get_color(), lw=1.2, ls="--", label="planned |f|")
    artists = [sim, plan]
    if drop_time is not None:
        artists.append(ax.axvspan(drop_time, t[-1], color="0.85", zorder=0, lw=0,
                                  label="after the drop (may be clipped)"))
    return artists


def plot_segments(ax, spans, finger: int | None = None, *, color="gold"):
    """Segment boundaries (dotted) of spans [(t_start, t_end, switching finger or None)];
    the segments in which `finger` switches are shaded."""
    artists = [ax.axvline(t0, color="0.5", ls=":", lw=0.8, zorder=0) for t0, _, _ in spans[1:]]
    for t0, t1, switching in spans:
        if finger is not None and switching == finger:
            artists.append(ax.axvspan(t0, t1, color=color, alpha=0.25, lw=0, zorder=0,
                                      label="segment in which this finger switches"))
    return artists


def plot_contacts(ax, pose, p_BC, n_B, *, colors=FINGER_COLORS, size=18):
    """Contact points p_BC (k, 2) of the box at `pose`, one colour per finger, with their
    outward normals n_B as short arrows."""
    p_W = np.array([box_to_world(pose, p) for p in p_BC])
    n_W = np.array([box_to_world((0.0, 0.0, pose[2]), n) for n in n_B])
    artists = [ax.scatter(p_W[:, 0], p_W[:, 1], s=size, c=list(colors[:len(p_W)]), edgecolors="k", zorder=6)]
    artists.append(ax.quiver(p_W[:, 0], p_W[:, 1], n_W[:, 0], n_W[:, 1], angles="xy", scale_units="xy",
                             scale=1 / 0.02, width=0.004, color="k", zorder=6))
    return artists


def plot_friction_cones(ax, pose, p_BC, n_B, mu: float, *, length=0.03, color="tab:cyan", alpha=0.4):
    """The friction cone of each contact: the forces a finger can apply on the box,
    -n + [-mu, mu] t, drawn as a wedge from the contact point into the box."""
    artists = []
    for p, n in zip(p_BC, n_B):
        t = np.array([-n[1], n[0]])
        edges = [(-n + sign * mu * t) / np.hypot(1.0, mu) for sign in (-1.0, 1.0)]
        wedge = [box_to_world(pose, p)] + [box_to_world(pose, p + length * e) for e in edges]
        artists.append(ax.add_patch(Polygon(np.array(wedge), closed=True, facecolor=color, edgecolor=color,
                                            alpha=alpha, zorder=5)))
    return artists


def plot_contact_node(ax, scene, node, *, mu: float, previous=None):
    """One node of a contact plan (a ContactNode) like the paper's Fig. 1 keyframes: box,
    hand at the node's joint angles, contacts with friction cones; the switching finger is
    drawn thick, with its previous contact (from `previous`, a ContactNode) as a hollow marker."""
    c = scene.config
    artists = plot_box(ax, c.box_width, c.box_height, node.object_pose)
    for i, finger in enumerate(scene.fingers):
        switching = i == node.switching_finger
        artists += plot_finger(ax, finger, node.q[2 * i:2 * i + 2], scene.tip_radius,
                               color="k" if switching else "0.55", lw=4.0 if switching else 2.0,
                               tip_color=FINGER_COLORS[i])
        artists.append(ax.annotate(str(i), finger.p_W_base, xytext=(0, -10 if finger.p_W_base[1] < 0 else 4),
                                   textcoords="offset points", ha="center", fontsize=7, color=FINGER_COLORS[i],
                                   fontweight="bold"))
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
        Line2D([], [], marker="o", ls="none", mfc="0.6", mec="k", ms=6, label="contact (finger's colour; arrow: normal)"),
        Patch(facecolor="tab:cyan", alpha=0.4, label=f"friction cone (mu = {mu:.2g})"),
        Line2D([], [], marker="o", ls="none", mfc="none", mec="0.3", ms=7, mew=1.5,
               label="switching finger's previous contact"),
        Line2D([], [], color="k", lw=4.0, label="switching finger"),
        Line2D([], [], color="0.55", lw=2.0, label="holding fingers (numbered at their bases)"),
    ]
