"""Plots of a sweep's statistics: each function draws on a given matplotlib `ax` and
returns its artists; the figures are assembled in trajectotree.experiments.report. The drawing of one
plan or one run (box, hand, keyframes, forces) is in trajectotree.figures.run.
"""

from __future__ import annotations

import numpy as np


def plot_boxes_with_means(ax, samples, labels, *, colors=None, mean_marker="x"):
    """Standard box plots (median, quartiles, 1.5 IQR whiskers, outliers) of each 1-D
    sample, with the sample means marked by crosses (the paper's Fig. 2). An empty
    sample's slot says "no data"; with no data at all the value axis has no ticks."""
    samples = [np.asarray(s, dtype=float) for s in samples]
    positions = np.arange(1, len(samples) + 1)
    parts = ax.boxplot(
        samples,
        positions=positions,
        tick_labels=labels,
        patch_artist=True,
        widths=0.5,
        medianprops={"color": "k"},
        flierprops={"marker": ".", "markersize": 4},
    )
    for patch, color in zip(parts["boxes"], colors or ()):
        patch.set_facecolor(color)
        patch.set_alpha(0.5)
    filled = [(p, s.mean()) for p, s in zip(positions, samples) if s.size]
    means = ax.plot(
        [p for p, _ in filled],
        [m for _, m in filled],
        mean_marker,
        color="k",
        ms=8,
        mew=2,
        ls="none",
        label="mean",
        zorder=5,
    )
    empty = [
        ax.text(
            p, 0.5, "no data", transform=ax.get_xaxis_transform(), ha="center", va="center", color="0.45", fontsize=9
        )
        for p, s in zip(positions, samples)
        if not s.size
    ]
    if not filled:
        ax.set_yticks([])  # matplotlib's default -0.05..0.05 would read as values
    return [artist for group in parts.values() for artist in group] + means + empty


def plot_mean_band(ax, t, mean, lower, upper, *, color=None, label=None, alpha=0.25):
    """A mean curve over t with a shaded band between lower and upper (e.g. a 95%
    confidence interval, the paper's Fig. 3)."""
    (line,) = ax.plot(t, mean, color=color, label=label, lw=1.5)
    band = ax.fill_between(t, lower, upper, color=line.get_color(), alpha=alpha, lw=0)
    return [line, band]
