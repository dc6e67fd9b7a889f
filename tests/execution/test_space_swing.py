"""A swinging finger in space (execution.space_control.swing_timing, SwingLift, space_schedule): it unloads on its
lift-off point, rises straight off it, travels the plan's path lifted clear of the cube from rest to rest at a
bounded speed, and descends onto its landing point before it loads there; on seed-0 goal 1's first swing (the
plan's path from the top face to the side cuts 5 mm into the edge, 23 mm in 0.1 s) the stage-1 controller dragged
the cube off its grasp."""

import numpy as np
import pytest

from trajectotree.execution.space_control import SwingLift, swing_timing
from trajectotree.geometry import box_signed_distances

HALF = (0.0325, 0.0325, 0.0325)  # m, fingerpro4's cube
TIP_RADIUS, LIFT, RAMP = 0.01, 0.008, 0.1  # m, m, s
PERIOD = 0.002  # s, the controller's


def _edge_swing():
    """Knots 0.1 s apart: on the top face (in contact) until 1.0 s, then the straight path over the +y edge that
    goal 1's plan takes (its first knot off the cube 3 mm from the side face), landing on the side at 2.0 s."""
    t = np.round(np.arange(0.0, 3.01, 0.1), 10)
    top, side = np.array([0.0, 0.0225, 0.0425]), np.array([0.0, 0.0425, 0.0])
    first_off = np.array([-0.00988, 0.04559, 0.03094])
    p = np.empty((len(t), 3))
    p[t <= 1.0] = top
    p[t >= 2.0] = side
    swing = (t > 1.0) & (t < 2.0)
    p[swing] = first_off + (side - first_off) * ((t[swing] - 1.1) / 0.9)[:, None]
    in_contact = ~swing
    return t, p, in_contact


@pytest.fixture(scope="module")
def timing():
    t, p, in_contact = _edge_swing()
    times = np.arange(int(round(3.0 / PERIOD)) + 1) * PERIOD
    return times, swing_timing(times, t, in_contact, p, RAMP, SwingLift(HALF, TIP_RADIUS, LIFT))


def test_the_plans_straight_path_cuts_into_the_cube():
    """The reproducer's premise: the plan's own path between its knots passes 5 mm into the edge."""
    t, p, _ = _edge_swing()
    u = np.linspace(0.0, 1.0, 101)[:, None]
    segment = p[10] + u * (p[11] - p[10])
    assert box_signed_distances(HALF, segment).min() - TIP_RADIUS < -0.004


def test_the_finger_unloads_on_its_point_then_rises_straight_off(timing):
    times, w = timing
    hold = (times > 1.0) & (times < 1.0 + RAMP)
    assert w.lifting[hold].all() and not w.lifting[~hold].any()
    np.testing.assert_allclose(w.p_B[hold], [[0.0, 0.0225, 0.0425]] * hold.sum(), atol=1e-12)  # on its point
    assert w.scale[np.argmin(np.abs(times - (1.0 + RAMP)))] == pytest.approx(0.0, abs=1e-9)
    assert w.scale[times <= 1.0].min() == 1.0 and w.scale[times >= 2.0].min() == 1.0
    rise = (times >= 1.0 + RAMP) & (times <= 1.0 + 2 * RAMP)
    np.testing.assert_allclose(w.p_B[rise][:, :2], [[0.0, 0.0225]] * rise.sum(), atol=1e-12)  # straight up
    assert np.all(np.diff(w.p_B[rise][:, 2]) >= 0.0)
    assert w.p_B[rise][-1, 2] == pytest.approx(0.0425 + LIFT, abs=1e-9)


def test_the_travel_is_clear_of_the_cube_smooth_and_from_rest_to_rest(timing):
    times, w = timing
    travel = (times >= 1.0 + 2 * RAMP) & (times <= 2.0 - 2 * RAMP)
    gap = box_signed_distances(HALF, w.p_B[travel]) - TIP_RADIUS
    assert gap.min() >= LIFT - 5e-4  # m: between the lifted path's samples the chord cuts its arc round the edge
    speed = np.linalg.norm(np.gradient(w.p_B, times, axis=0), axis=1)
    assert speed[travel].max() < 0.3  # m/s; the plan's own time law: 0.26 m/s on average over its first 0.1 s
    for end in (1.0 + RAMP, 1.0 + 2 * RAMP, 2.0 - 2 * RAMP, 2.0 - RAMP):
        assert speed[np.argmin(np.abs(times - end))] < 0.02
    carry = w.carry[travel]
    assert (
        carry[0] == pytest.approx(1.0) and carry[-1] == pytest.approx(0.0, abs=1e-5) and np.all(np.diff(carry) <= 1e-12)
    )


def test_the_finger_lands_on_the_plans_point(timing):
    times, w = timing
    landing = (times > 2.0 - RAMP) & (times <= 2.0)
    np.testing.assert_allclose(w.p_B[landing], [[0.0, 0.0425, 0.0]] * landing.sum(), atol=1e-9)
    np.testing.assert_allclose(w.p_B[times < 1.0], [[0.0, 0.0225, 0.0425]] * int((times < 1.0).sum()), atol=1e-12)
