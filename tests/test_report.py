"""The report: the paper's Figs. 2-3 and the summary table from a sweep directory."""

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.report import tracking_bands

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
