"""The physics check of plan arrays (trajectotree.planning.physics) against closed forms: the
exact box distance and nearest boundary points against geometry.ConvexPolygon, and a
box held at rest by four forces that balance gravity, then broken one way at a time."""

import json

import numpy as np
import pytest

from trajectotree.geometry import ConvexPolygon, rotation_2d
from trajectotree.planning.physics import (
    FORCE_TOL,
    GAP_TOL,
    PENETRATION_TOL,
    ObjectModel,
    PhysicsCheck,
    check_physics,
    contact_points,
)

W, H, R = 0.20, 0.10, 0.01
BOX = ObjectModel(mass=0.05, shape=ConvexPolygon.box(W, H), gravity=9.81, tip_radius=R)


def test_distance_and_nearest_points_match_the_scalar_ones():
    box = ConvexPolygon.box(W, H)
    p = np.random.default_rng(0).uniform(-0.15, 0.15, (400, 2))
    np.testing.assert_allclose(box.signed_distances(p), [box.signed_distance(q) for q in p], atol=1e-15)
    np.testing.assert_allclose(box.nearest_points(p), [box.project(q) for q in p], atol=1e-15)


def hold(K=5, pose=(0.01, -0.02, 0.3)):
    """Arrays of a box at rest at `pose`: fingers 1, 2 on top press with 0.5 N each, fingers
    0, 3 under it push back and carry the weight (gravity expressed in B, so the tangential
    parts and the moment balance at any theta)."""
    R_WB = rotation_2d(pose[2])
    p_BC = np.array([[0.05, -H / 2], [-0.05, H / 2], [0.05, H / 2], [-0.05, -H / 2]])
    n_B = np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]])
    g_B = R_WB.T @ np.array([0.0, -BOX.mass * BOX.gravity])
    side = -g_B[0] / 2  # tangential force of each bottom finger
    d = -H / 2 * 2 * side / 0.1  # their normal forces differ by 2 d: no moment
    f_B = np.array([[side, 0.5 - g_B[1] / 2 + d], [0.0, -0.5], [0.0, -0.5], [side, 0.5 - g_B[1] / 2 - d]])
    t_B = n_B @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # t = z x n
    ln, lt = -np.sum(f_B * n_B, axis=1), np.sum(f_B * t_B, axis=1)
    f_W, p_W_C = f_B @ R_WB.T, pose[:2] + p_BC @ R_WB.T
    p_W_tip = pose[:2] + (p_BC + R * n_B) @ R_WB.T
    return {
        "t": np.linspace(0.0, 1.0, K),
        "x": np.tile(pose, (K, 1)),
        "xdot": np.zeros((K, 3)),
        "lambda_n": np.tile(ln, (K, 1)),
        "lambda_t": np.tile(lt, (K, 1)),
        "f_W": np.tile(f_W, (K, 1, 1)),
        "p_W_tip": np.tile(p_W_tip, (K, 1, 1)),
        "p_W_C": np.tile(p_W_C, (K, 1, 1)),
    }


def test_a_held_box_passes():
    check = check_physics(hold(), BOX, mu=0.7)
    assert check.passed, check.reason
    assert check.newton_euler_force_N < 1e-12 and check.newton_euler_moment_Nm < 1e-12
    assert check.force_at_distance_N == 0.0 and check.contact_point_off_surface_m < 1e-15
    assert check.penetration_m < 1e-15


def test_a_fingertip_off_the_box_may_not_push():
    a = hold()
    normal = (a["p_W_tip"][:, 2] - a["p_W_C"][:, 2]) / R
    a["p_W_tip"][:, 2] += 2 * GAP_TOL * normal  # finger 2 lifted 0.2 mm, same force
    check = check_physics(a, BOX, mu=0.7)
    assert not check.passed and check.force_at_distance_finger == 2
    assert check.force_at_distance_N == pytest.approx(0.5) and check.force_at_distance_gap_m == pytest.approx(2e-4)
    assert "finger 2" in check.reason and "0.20 mm" in check.reason
    a["f_W"][:, 2] *= 0.5 * FORCE_TOL / 0.5  # a force below the limit is allowed there
    assert check_physics(a, BOX, mu=0.7).force_at_distance_N <= FORCE_TOL


def test_a_fingertip_may_not_sink_into_the_box():
    a = hold()
    inward = (a["p_W_C"][:, 3] - a["p_W_tip"][:, 3]) / R
    a["p_W_tip"][:, 3] += 0.5 * PENETRATION_TOL * inward  # 0.5 mm deep: within the limit
    check = check_physics(a, BOX, mu=0.7)
    assert check.passed and check.penetration_m == pytest.approx(0.5 * PENETRATION_TOL)
    a["p_W_tip"][2:, 3] += 1.5 * PENETRATION_TOL * inward[2:]  # 2 mm deep from knot 2
    check = check_physics(a, BOX, mu=0.7)
    assert not check.passed and check.penetration_m == pytest.approx(2 * PENETRATION_TOL)
    assert "finger 3 sinks 2.00 mm into the box at knot 2" in check.reason


def test_friction_and_newton_euler_violations_are_found():
    a = hold()
    a["lambda_t"][:, 1] = 0.5 * 0.6  # |lambda_t| = 0.6 lambda_n
    assert check_physics(a, BOX, mu=0.7).friction_cone_N <= 0.0
    check = check_physics(a, BOX, mu=0.5)
    assert check.friction_cone_N == pytest.approx(0.05) and "friction cone" in check.reason
    b = hold()
    b["p_W_C"][:, 1] += np.array([0.003, 0.0])  # 3 mm along W x: moment 3 mm * f_y
    check = check_physics(b, BOX, mu=0.7)
    assert check.newton_euler_moment_Nm == pytest.approx(0.003 * 0.5 * np.cos(0.3), rel=1e-6)
    assert "Newton-Euler" in check.reason
    c = hold()
    c["xdot"][-1, 0] = 0.01  # accelerates with no net force
    assert check_physics(c, BOX, mu=0.7).newton_euler_force_N == pytest.approx(BOX.mass * 0.01 / 0.25)


def test_contact_points_are_planned_where_pinned_else_nearest():
    x = np.array([[0.02, 0.01, 0.4]] * 2)
    R_WB = rotation_2d(0.4)
    p_BC_planned = np.tile([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.02], [0.03, -0.05]], (2, 1, 1))
    tips_B = np.array([[0.12, 0.01], [0.01, 0.07], [-0.13, 0.08], [0.0, -0.061]])  # finger 2 beyond a corner
    p_W_tip = np.tile(x[0, :2] + tips_B @ R_WB.T, (2, 1, 1))
    pinned = np.array([[True, True, False, False], [False, False, False, False]])
    p_W_C = contact_points(x, p_W_tip, pinned, p_BC_planned, BOX.shape)
    expected = np.array([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.05], [0.0, -0.05]])
    np.testing.assert_allclose(p_W_C[0], x[0, :2] + expected @ R_WB.T, atol=1e-15)
    np.testing.assert_allclose(p_W_C[1, :2], x[0, :2] + np.array([[0.1, 0.01], [0.01, 0.05]]) @ R_WB.T, atol=1e-15)


def test_non_finite_plans_fail_and_the_check_round_trips_through_json():
    a = hold()
    a["xdot"][2, 1] = np.nan
    check = check_physics(a, BOX, mu=0.7)
    assert not check.passed and "non-finite" in check.reason
    data = json.loads(json.dumps(check.to_json(), allow_nan=False))
    assert data["newton_euler_force_N"] is None and data["force_tol_N"] == FORCE_TOL
    back = PhysicsCheck.from_json(data)
    assert np.isnan(back.newton_euler_force_N) and back.reason == check.reason
    ok = check_physics(hold(), BOX, mu=0.7)
    assert (
        PhysicsCheck.from_json(json.loads(json.dumps(ok.to_json()))).to_json() == ok.to_json()
    )  # NaN: unchecked links
    older = {k: v for k, v in ok.to_json().items() if k != "penetration_m"}  # a plan.json from before the rule
    assert np.isnan(PhysicsCheck.from_json(older).penetration_m)
