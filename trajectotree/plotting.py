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
