"""The keyframes formulation in space keeps the switching fingertip off the others (cito.spatial.TIP_GAP): its rows'
bounds on the lifted knots only, their Jacobian columns against central differences, and a solved segment whose
swinging fingertip stays 2 r + TIP_GAP from every other at every knot."""

import math

import numpy as np
import pytest
from conftest import jacobian_against_differences

from trajectotree.cito import spatial as sp
from trajectotree.config import Config, mu_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.tree import find_space_contact_plan

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="module")
def switch():
    """A segment of the quarter turn about x in which a finger switches: (scene, fingers, its spec, mu)."""
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    plan = find_space_contact_plan(scene, QUARTER_ABOUT_X, config.search, mu)
    assert plan.success, plan.reason
    fingers = sp.space_fingers(scene)
    k = next(k for k, node in enumerate(plan.nodes) if node.switching_finger is not None)
    return scene, fingers, sp.segment_spec(scene, fingers, plan.nodes[k - 1], plan.nodes[k]), mu


def test_the_tip_rows_bound_the_lifted_knots_alone(switch):
    scene, fingers, spec, mu = switch
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, sp.SPACE_INTERVALS, sp.SPACE_DT)
    lo, hi = rows.knot_bounds()
    tips = lo[:, rows.tip_row : rows.link_row]
    least = (2 * scene.tip_radius + sp.TIP_GAP) ** 2 * rows.tip_scale
    others = [i for i in range(scene.num_fingers) if i != spec.switching]
    np.testing.assert_allclose(tips[1:-1, others], least)
    assert np.all(np.isneginf(tips[[0, -1]])) and np.all(np.isneginf(tips[:, spec.switching]))
    assert np.all(np.isposinf(hi[:, rows.tip_row : rows.link_row]))


def test_the_tip_columns_match_central_differences(switch):
    scene, fingers, spec, mu = switch
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, 4, sp.SPACE_DT)
    Z = sp._guess(rows) + 1e-3 * np.random.default_rng(2).standard_normal((rows.K, rows.layout.width))
    J, numeric, pattern = jacobian_against_differences(sp._SegmentConstraint(rows), Z)
    Rk = sp._SegmentConstraint(rows).num_knot_rows
    tip_rows = np.concatenate([k * Rk + np.arange(rows.tip_row, rows.link_row) for k in range(rows.K)])
    assert np.any(J[tip_rows])  # the rows are live
    np.testing.assert_allclose(J[tip_rows], numeric[tip_rows], atol=1e-6)


def test_a_solved_swing_keeps_its_fingertip_off_the_others(switch):
    scene, fingers, spec, mu = switch
    result = sp.solve_space_segment(scene, fingers, spec, mu, Config().cito)
    assert result.success, result.status
    tips = result.p_W_tip  # (K, F, 3)
    d = np.linalg.norm(tips[:, [spec.switching]] - tips, axis=-1)
    d[:, spec.switching] = np.inf
    assert d[1:-1].min() >= 2 * scene.tip_radius + sp.TIP_GAP - 1e-6
