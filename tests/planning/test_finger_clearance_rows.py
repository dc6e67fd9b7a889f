"""Fingers kept apart by the trajectory optimization and checked in plan.npz: the physics check's
finger rule on a real plan edited to put two fingers into each other, and CITO's finger rows
(their Jacobian, that they are conservative, and which pairs get them)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from trajectotree.cito.fingers import FingerRows, near_pairs
from trajectotree.cito.knot import BodyParams
from trajectotree.config import Config, mu_plan
from trajectotree.io import load_plan
from trajectotree.planning.physics import ObjectModel, check_physics
from trajectotree.scene.finger_clearance import pair_distances
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import grasp_joints
from trajectotree.search.reach import Reachability

OVERLAPPING = (0.08, 0.02, 0.38, 0.32)  # a grid grasp with fingertip 0 11.3 mm inside finger 1's link 2
ALL_PAIRS = tuple(itertools.combinations(range(4), 2))


@pytest.fixture(scope="module")
def scene():
    return build_scene(Config().scene)


def random_joints(scene, count: int, seed: int) -> np.ndarray:
    lower = np.concatenate([f.q_lower for f in scene.fingers])
    upper = np.concatenate([f.q_upper for f in scene.fingers])
    return np.random.default_rng(seed).uniform(lower, upper, (count, len(lower)))


def test_the_physics_check_refuses_a_plan_whose_fingers_overlap(tiny_plan, scene):
    result = load_plan(tiny_plan)
    arrays = result.trajectory.arrays()
    box, mu = ObjectModel.from_scene(scene), mu_plan(result.config.scene, result.config.search)
    clean = check_physics(arrays, box, mu)
    assert clean.passed and clean.finger_distance_m > 0.002
    k = len(arrays["t"]) // 2
    q = arrays["q"].copy()
    q[k] = grasp_joints(scene, Reachability(scene), np.array([OVERLAPPING]))[0]
    edited = check_physics(arrays | {"q": q}, box, mu)
    assert not edited.passed
    assert edited.finger_distance_knot == k and edited.finger_distance_fingers in ((0, 1), (2, 3))
    assert edited.finger_distance_m == pytest.approx(-0.011256, abs=1e-6)
    i, j = edited.finger_distance_fingers
    assert f"fingers {i} and {j} overlap by 11.26 mm at knot {k} (limit 1 mm)" in edited.reason
    assert type(edited).from_json(edited.to_json()).finger_distance_fingers == (i, j)


def test_finger_rows_jacobian_matches_finite_differences(scene):
    rows = FingerRows(BodyParams(scene, 1000.0, mu=0.49), ALL_PAIRS, 3)
    Z = random_joints(scene, 3, seed=0)
    values, jac = rows.evaluate(Z, True)
    h, numeric = 1e-7, np.zeros_like(jac)
    for c in range(Z.shape[1]):
        step = np.zeros(Z.shape[1])
        step[c] = h
        numeric[:, :, c] = (rows.evaluate(Z + step, False)[0] - rows.evaluate(Z - step, False)[0]) / (2 * h)
    assert np.abs(jac - numeric).max() < 1e-6
    assert set(zip(*np.nonzero(np.abs(jac).max(axis=0)))) <= set(rows.sparsity())
    assert np.array_equal(rows.values_one(Z[1]), values[1])


def test_finger_rows_never_see_more_room_than_the_exact_distance_where_fingers_are_near(scene):
    """The capsules contain the link boxes: where two fingers are apart but within 50 mm (where rows
    matter; the nearest features then involve an elbow or a fingertip, not a base), a pair's least
    row never exceeds their exact gap."""
    rows = FingerRows(BodyParams(scene, 1000.0, mu=0.49), ALL_PAIRS, 1)
    Z = random_joints(scene, 4000, seed=1)
    values = rows.evaluate(Z, False)[0]  # rows grouped per pair: 9 each, in ALL_PAIRS's order
    exact = pair_distances(scene.fingers, Z, scene.tip_radius)
    near = 0
    for n, pair in enumerate(ALL_PAIRS):
        close = (exact[pair] >= 0.0) & (exact[pair] < 0.05)
        near += int(close.sum())
        assert np.all(values[close, 9 * n : 9 * n + 9].min(axis=1) <= exact[pair][close] + 1e-12)
    assert near > 1000


def test_only_pairs_near_each_other_on_the_nodes_path_get_rows(scene):
    overlapping = grasp_joints(scene, Reachability(scene), np.array([OVERLAPPING]))[0]
    pairs = near_pairs(scene.fingers, [overlapping, overlapping], scene.tip_radius)
    assert pairs == ((0, 1), (2, 3))  # the opposite pairs stay 0.1 m and more apart
    assert near_pairs(scene.fingers, [overlapping, overlapping], scene.tip_radius, margin=-0.1) == ()
