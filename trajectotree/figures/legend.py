"""What the pictures of a run share and need no plotting library for: each finger's colour, the force
arrows' scale (one per run, stated in every picture), each arrow's ends and the controllers' names. The PNG figures
(trajectotree.figures.run), Meshcat and the HTML playback (trajectotree.execution.playback_page) and the
simulation's arrow scale all read them here, so building a simulation loads no matplotlib.
"""

from __future__ import annotations

import math

import numpy as np

# a colour per finger, the four-finger hand's first (a hand of more fingers takes the next ones)
FINGER_COLORS = ("tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
# the same colours as matplotlib's Tableau palette writes them, for the pictures drawn without matplotlib
FINGER_HEX = ("#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#bcbd22", "#17becf")
ARROW_TARGET_LENGTH = 0.05  # m, the largest force that sets an arrow scale is drawn at most this long
ARROW_MAX_LENGTH = 0.12  # m, longer arrows are capped (a dropped box squeezed between the fingers)
ARROW_MIN_FORCE = 0.02  # N, a smaller force (a finger off the box) draws no arrow


def arrow_newtons_per_cm(forces) -> float:
    """The force arrows' scale, N per cm of arrow: the smallest of 1, 2, 5 x 10^k N/cm that
    draws the largest |f| of `forces` (..., 2) at most ARROW_TARGET_LENGTH long (1 N/cm
    without forces), so that every picture of one run states one round scale."""
    top = float(np.max(np.linalg.norm(np.asarray(forces, dtype=float), axis=-1), initial=0.0))
    if top <= ARROW_MIN_FORCE:
        return 1.0
    raw = top / (100 * ARROW_TARGET_LENGTH)
    decade = 10.0 ** math.floor(math.log10(raw))
    return next(m * decade for m in (1, 2, 5, 10) if m * decade >= raw * (1 - 1e-12))


def arrow_scale_text(newtons_per_cm: float) -> str:
    """How the pictures state an arrow scale, e.g. "1 cm = 0.2 N" (capped at ARROW_MAX_LENGTH)."""
    return f"1 cm = {newtons_per_cm:g} N, capped at {100 * ARROW_MAX_LENGTH:g} cm"


def force_arrow(tip, f, tip_radius: float, newtons_per_cm: float):
    """(start, end) in W of the arrow of force f (2,) in the plane or (3,) in space of a finger on the object,
    or None for |f| < ARROW_MIN_FORCE: from the fingertip sphere's surface (its centre `tip`, (2,) or (3,)) in the
    force's direction (where it touches the object) along f, |f| / newtons_per_cm cm long, capped at
    ARROW_MAX_LENGTH."""
    f = np.asarray(f, dtype=float)
    magnitude = float(np.linalg.norm(f))
    if magnitude < ARROW_MIN_FORCE:
        return None
    direction = f / magnitude
    start = np.asarray(tip, dtype=float) + tip_radius * direction
    return start, start + min(magnitude / newtons_per_cm / 100, ARROW_MAX_LENGTH) * direction


def finger_rgb(i: int) -> tuple[float, float, float]:
    """Finger i's colour (FINGER_HEX), RGB in [0, 1], as matplotlib's to_rgb gives it."""
    h = FINGER_HEX[i]
    return tuple(int(h[k : k + 2], 16) / 255 for k in (1, 3, 5))


CONTROLLER_NAMES = {
    "grasp": "grasp controller",
    "paper": "paper's controller (eq. 20)",
    "none": "no controller (zero torque)",
}


def controller_text(controller: str) -> str:
    """What the figures call a SimLog's controller, e.g. "grasp controller"."""
    return CONTROLLER_NAMES.get(controller, f"{controller} controller")
