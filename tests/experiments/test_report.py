"""The report: the paper's Figs. 2-3 and the summary table from a sweep directory."""

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.experiments.report import tracking_bands

T_975 = {1: 12.706204736174698}  # Student-t 0.975 quantile, 1 degree of freedom


def test_tracking_bands_on_a_common_grid_match_closed_form():
    # Trial A spans 0-2 s with error t in every component; trial B spans 0-1 s with error 1.
    a = (np.array([0.0, 1.0, 2.0]), np.repeat(np.array([[0.0], [1.0], [2.0]]), 3, axis=1))
    b = (np.array([0.0, 0.5, 1.0]), np.ones((3, 3)))
    grid = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    mean, lower, upper = tracking_bands([a, b], grid)
    both = np.array([[0.0, 1.0], [0.5, 1.0], [1.0, 1.0]])  # samples at 0, 0.5, 1 s
    half = T_975[1] * both.std(axis=1, ddof=1) / np.sqrt(2)
    for c in range(3):
        np.testing.assert_allclose(mean[:3, c], both.mean(axis=1))
        np.testing.assert_allclose(upper[:3, c] - mean[:3, c], half)
        np.testing.assert_allclose(mean[:3, c] - lower[:3, c], half)
        np.testing.assert_allclose(mean[3:, c], [1.5, 2.0])  # only A covers 1.5 and 2 s
        np.testing.assert_allclose(lower[3:, c], mean[3:, c])


def test_report_of_a_missing_sweep_is_an_input_error(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nothing")]) == 2
    assert "not a sweep directory" in capsys.readouterr().err


@pytest.mark.slow
def test_report_of_a_small_sweep_has_every_figure_and_the_table(resumed_sweep, tmp_path, capsys):
    import csv
    import json

    from trajectotree.experiments.sweep_store import read_rows

    assert main(["report", str(resumed_sweep.out), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    for stem in ("fig2_time_cost", "fig3_tracking"):
        assert (tmp_path / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (tmp_path / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-"
        assert str(tmp_path / f"{stem}.png") in printed
    table = list(csv.DictReader((tmp_path / "summary.csv").open()))
    markdown = (tmp_path / "summary.md").read_text()
    assert [t["method"] for t in table] == ["trajectotree", "cito-warm"]
    rows = read_rows(resumed_sweep.out)
    for t in table:  # the table's numbers are those of the trial rows
        mine = [r for r in rows if r["method"] == t["method"]]
        assert float(t["success_rate"]) == pytest.approx(np.mean([bool(r["success"]) for r in mine]))
        assert float(t["converged_rate"]) == pytest.approx(np.mean([bool(r["converged"]) for r in mine]))
        assert float(t["mean_time_s"]) == pytest.approx(np.mean([r["total_time_s"] for r in mine]))
        executed = [r for r in mine if r["simulated"]]
        assert int(t["simulated"]) == len(executed)
        if executed:
            assert float(t["drop_rate"]) == pytest.approx(np.mean([bool(r["dropped"]) for r in executed]))
            assert float(t["mae_theta"]) == pytest.approx(np.mean([r["mae_theta"] for r in executed]))
    assert table[0]["paper_mean_time_s"] == "14.0" and table[1]["paper_mean_time_s"] == "76.0"
    assert "| TrajectoTree |" in markdown and "| CITO, warm-start |" in markdown and "5.4x" in markdown
    assert main(["report", str(resumed_sweep.out), "--out", str(tmp_path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["table"][0]["method"] == "trajectotree"


# ---- the pictures ---------------------------------------------------------------


def test_time_and_cost_figure_says_no_data_instead_of_empty_axes():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.experiments.report import figure_time_and_cost

    rows = [
        {"method": "trajectotree", "success": True, "total_time_s": 12.0, "cost": 250.0, "goal_index": 0},
        {"method": "cito", "success": None, "total_time_s": None, "cost": None, "goal_index": 0, "error": "timeout"},
    ]
    fig = figure_time_and_cost(rows, ["trajectotree", "cito"])
    ax_time, ax_cost = fig.axes
    assert [t.get_text() for t in ax_time.texts] == ["no data"]  # CITO's slot
    assert ax_time.texts[0].get_position()[0] == 2 and len(ax_time.get_yticks()) > 0
    plt.close(fig)
    fig = figure_time_and_cost(rows[1:], ["cito"])  # nothing at all: no meaningless ticks
    assert all([t.get_text() for t in ax.texts] == ["no data"] and len(ax.get_yticks()) == 0 for ax in fig.axes)
    assert fig.axes[0].get_legend() is None
    plt.close(fig)


def test_tracking_figure_plots_x_and_y_in_mm_and_names_the_band():
    """Fig. 3 in the tables' units: x and y errors in mm (the curves are 1000 x the metres of
    sim.npz), theta in rad; the legend names each method's mean and the shaded 95 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from trajectotree.experiments.report import figure_tracking

    t = np.linspace(0.0, 1.0, 11)
    trials = [(t, np.column_stack([0.002 * t, 0.001 + 0 * t, 0.05 * t])) for _ in range(2)]
    trials.append((t, np.column_stack([0.004 * t, 0.003 + 0 * t, 0.02 * t])))
    fig = figure_tracking({"trajectotree": trials}, ["trajectotree", "cito"])
    axes = fig.axes[:3]
    assert [ax.get_ylabel() for ax in axes] == [
        "mean absolute error, x [mm]",
        "mean absolute error, y [mm]",
        r"mean absolute error, $\theta$ [rad]",
    ]
    for ax, expected in zip(axes, (1e3 * 0.008 / 3 * t, np.full(11, 1e3 * 0.005 / 3), 0.12 / 3 * t)):
        np.testing.assert_allclose(ax.lines[0].get_ydata(), expected)
    labels = [text.get_text() for text in fig.legends[0].get_texts()]
    assert labels == ["TrajectoTree mean (n=3)", "shaded: 95 % CI of the mean (Student t, across trials)"]
    assert [t.get_text() for t in fig.texts] == ["no executed plans: CITO"]
    plt.close(fig)
