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
    sample leaves its slot blank."""
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
    return [artist for group in parts.values() for artist in group] + means


def plot_mean_band(ax, t, mean, lower, upper, *, color=None, label=None, alpha=0.25):
    """A mean curve over t with a shaded band between lower and upper (e.g. a 95%
    confidence interval, the paper's Fig. 3)."""
    (line,) = ax.plot(t, mean, color=color, label=label, lw=1.5)
    band = ax.fill_between(t, lower, upper, color=line.get_color(), alpha=alpha, lw=0)
    return [line, band]
