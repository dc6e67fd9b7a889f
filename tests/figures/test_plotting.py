"""The sweep statistics' plots (trajectotree.figures.statistics) checked against the numbers they were given."""

import matplotlib
import numpy as np
import pytest

from trajectotree.figures.statistics import plot_boxes_with_means, plot_mean_band


def test_box_plots_mark_each_samples_mean_and_quartiles(ax):
    samples = [[1.0, 2.0, 3.0, 10.0], [], [4.0, 4.0, 5.0]]
    artists = plot_boxes_with_means(ax, samples, ["a", "b", "c"], colors=["red", "green", "blue"])
    means = [a for a in artists if isinstance(a, matplotlib.lines.Line2D) and a.get_label() == "mean"]
    np.testing.assert_allclose(np.column_stack(means[0].get_data()), [[1.0, 4.0], [3.0, 13.0 / 3.0]])
    medians = [line.get_ydata()[0] for line in ax.lines if line.get_color() == "k" and line.get_label() != "mean"]
    assert [m for m in medians if np.isfinite(m)] == pytest.approx([2.5, 4.0])  # the empty slot's is nan
    assert [t.get_text() for t in ax.texts] == ["no data"] and ax.texts[0].get_position()[0] == 2
    assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b", "c"]


def test_mean_band_spans_lower_to_upper(ax):
    t = np.linspace(0.0, 1.0, 4)
    mean, lower, upper = t**2, t**2 - 0.1, t**2 + 0.2
    line, band = plot_mean_band(ax, t, mean, lower, upper, color="tab:blue", label="m")
    np.testing.assert_allclose(line.get_ydata(), mean)
    outline = band.get_paths()[0].vertices
    for ti, lo, hi in zip(t, lower, upper):  # the band's outline passes through both bounds at each time
        at = outline[np.isclose(outline[:, 0], ti)]
        assert at[:, 1].min() == pytest.approx(lo) and at[:, 1].max() == pytest.approx(hi)
    assert matplotlib.colors.same_color(band.get_facecolor()[0][:3], matplotlib.colors.to_rgb("tab:blue"))
