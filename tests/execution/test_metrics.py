"""Tracking metrics against closed-form answers."""

import dataclasses
import math

import numpy as np
import pytest

from trajectotree.execution.metrics import (
    absolute_error,
    detect_drop,
    evaluate,
    final_error,
    hold_after_drop,
    mean_absolute_error,
    mean_confidence_interval,
)
from trajectotree.results import SimLog


def test_errors_of_a_known_offset():
    t = np.linspace(0.0, 1.0, 101)
    ref = np.column_stack([np.zeros_like(t), np.zeros_like(t), t])
    pose = ref + np.column_stack([0.002 * np.ones_like(t), -0.001 * t, -0.1 * t])
    err = absolute_error(pose, ref)
    assert err.shape == (101, 3)
    np.testing.assert_allclose(mean_absolute_error(err), [0.002, 0.0005, 0.05], rtol=1e-12)
    np.testing.assert_allclose(final_error(err), [0.002, 0.001, 0.1], rtol=1e-12)


def test_theta_error_is_not_wrapped():
    # A box that spun a full turn is 2 pi off, not on target.
    err = absolute_error([[0.0, 0.0, 2 * math.pi]], [[0.0, 0.0, 0.0]])
    assert err[0, 2] == pytest.approx(2 * math.pi)


def free_fall():
    """(t, planned pose at rest, pose of a box falling from it) over 1 s."""
    t = np.arange(0.0, 1.0, 0.01)
    ref = np.zeros((t.size, 3))
    fall = ref.copy()
    fall[:, 1] = -0.5 * 9.81 * t**2
    return t, ref, fall


def test_free_fall_is_detected_when_it_passes_the_drop_distance():
    t, ref, fall = free_fall()
    dropped, when = detect_drop(t, fall, ref, 0.05)
    assert dropped
    expected = t[np.argmax(0.5 * 9.81 * t**2 > 0.05)]  # first sample beyond 5 cm: sqrt(0.1/9.81) = 0.101 s
    assert when == pytest.approx(expected) and when == pytest.approx(0.11)
    # rotations alone do not count as a drop; a held box does not drop
    spin = ref.copy()
    spin[:, 2] = 3.0
    assert detect_drop(t, spin, ref, 0.05) == (False, None)


def test_error_is_held_after_the_drop():
    t, ref, fall = free_fall()
    _, when = detect_drop(t, fall, ref, 0.05)
    held = hold_after_drop(t, absolute_error(fall, ref), when)
    at_drop = np.flatnonzero(t == when)[0]
    np.testing.assert_array_equal(held[: at_drop + 1], absolute_error(fall, ref)[: at_drop + 1])
    assert np.all(held[at_drop:, 1] == held[at_drop, 1]) and held[-1, 1] == pytest.approx(0.5 * 9.81 * when**2)
    # without a drop nothing changes
    np.testing.assert_array_equal(hold_after_drop(t, absolute_error(fall, ref), None), absolute_error(fall, ref))


def test_a_logged_fall_evaluates_to_the_closed_form_metrics():
    t, ref, fall = free_fall()
    forces = np.ones((t.size, 4, 2))
    log = SimLog(
        t=t,
        x=fall,
        q=np.zeros((t.size, 8)),
        x_plan=ref,
        f_W=forces,
        f_W_plan=2 * forces,
        sim_time_s=0.5,
        controller="paper",
        conditions={"push": None},
    )
    result = evaluate(log, drop_distance=0.05, gravity=9.81)
    assert result.dropped and result.drop_time_s == pytest.approx(0.11)
    y_at_drop = 0.5 * 9.81 * 0.11**2  # the error is held there after the drop
    y = np.minimum(0.5 * 9.81 * t**2, y_at_drop)
    assert result.mae_y == pytest.approx(y.mean(), rel=1e-12) and result.mae_x == 0.0 and result.mae_theta == 0.0
    # the error at the end is the fall's, not the held one; the held one is the error at the drop
    assert result.final_error == pytest.approx((0.0, 0.5 * 9.81 * t[-1] ** 2, 0.0), rel=1e-12)
    assert result.error_at_drop == pytest.approx((0.0, y_at_drop, 0.0))
    np.testing.assert_allclose(result.abs_error[:, 1], y, rtol=1e-12)
    # the log passes through unchanged, and sim.json says what was run
    assert result.f_W is log.f_W and result.x_plan is log.x_plan and result.sim_time_s == 0.5
    summary = result.to_json()
    assert summary["controller"] == "paper" and summary["conditions"] == {"push": None}
    assert summary["num_samples"] == t.size and summary["duration_s"] == pytest.approx(0.99)
    held = evaluate(dataclasses.replace(log, x=ref), drop_distance=0.05, gravity=9.81)
    assert not held.dropped and held.drop_time_s is None and held.final_error == (0.0, 0.0, 0.0)
    assert held.error_at_drop is None and held.to_json()["error_at_drop"] is None


def test_a_box_caught_again_after_the_drop_rule_fired_ends_on_the_plan():
    """sim.json's final_error is where the run ended, error_at_drop the error the means hold."""
    t = np.arange(0.0, 1.0, 0.01)
    ref = np.zeros((t.size, 3))
    x = ref.copy()
    away = (t > 0.2) & (t < 0.4)  # 6 cm below the plan and turned 0.714 rad, then back on it
    x[away, 1], x[away, 2] = -0.06, 0.714
    forces = np.zeros((t.size, 4, 2))
    log = SimLog(
        t=t,
        x=x,
        q=np.zeros((t.size, 8)),
        x_plan=ref,
        f_W=forces,
        f_W_plan=forces,
        sim_time_s=0.1,
        controller="grasp",
        conditions={},
    )
    result = evaluate(log, drop_distance=0.05, gravity=9.81)
    assert result.dropped and result.drop_time_s == pytest.approx(t[away][0])
    assert result.final_error == (0.0, 0.0, 0.0)
    assert result.error_at_drop == pytest.approx((0.0, 0.06, 0.714))
    assert result.mae_theta == pytest.approx(0.714 * np.mean(t >= t[away][0]))  # held from the drop on
    summary = result.to_json()
    assert summary["final_error"] == [0.0, 0.0, 0.0] and summary["error_at_drop"] == pytest.approx([0.0, 0.06, 0.714])


def test_confidence_interval_matches_the_student_t_formula():
    samples = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    ci = mean_confidence_interval(samples)
    half = 2.7764451051977987 * np.std(samples, ddof=1) / math.sqrt(5)  # t_{0.975, 4}
    assert ci.count == 5
    assert ci.mean == pytest.approx(3.0)
    assert (ci.lower, ci.upper) == (pytest.approx(3.0 - half), pytest.approx(3.0 + half))


def test_confidence_interval_per_time_and_coordinate():
    rng = np.random.default_rng(0)
    samples = rng.normal(1.0, 0.5, (60, 7, 3))  # trials x times x (x, y, theta)
    ci = mean_confidence_interval(samples, 0.95, axis=0)
    assert ci.mean.shape == ci.lower.shape == ci.upper.shape == (7, 3)
    assert np.all(ci.lower < ci.mean) and np.all(ci.mean < ci.upper)
    wider = mean_confidence_interval(samples, 0.99, axis=0)
    assert np.all(wider.upper - wider.lower > ci.upper - ci.lower)


def test_confidence_interval_coverage_is_about_95_percent():
    rng = np.random.default_rng(1)
    covered = 0
    for _ in range(2000):
        ci = mean_confidence_interval(rng.normal(2.0, 1.0, 8))
        covered += ci.lower <= 2.0 <= ci.upper
    assert 0.93 < covered / 2000 < 0.97


def test_confidence_interval_edge_cases():
    one = mean_confidence_interval([0.3])
    assert one.count == 1 and one.lower == one.mean == one.upper == pytest.approx(0.3)
    with pytest.raises(ValueError, match="NaN"):
        mean_confidence_interval([1.0, float("nan")])
    with pytest.raises(ValueError, match="at least one"):
        mean_confidence_interval([])
    with pytest.raises(ValueError, match="confidence"):
        mean_confidence_interval([1.0, 2.0], confidence=1.5)
