"""Fingers kept apart in space (issue 37): the finger-finger rows of the space segment programs
(cito.space_fingers) against a brute-force distance of fingerpro4's collision capsules from the plant's own
kinematics, their gradient against central differences (alone and scattered into a segment's constraint), the
closed-form nearest points of two segments against sampling, and the physics check in space refusing a plan
whose fingers overlap."""

import numpy as np
import pytest
from conftest import jacobian_against_differences

from trajectotree.cito import space_hand
from trajectotree.cito import spatial as sp
from trajectotree.cito.space_fingers import CLEARANCE, FingerParts, SpaceFingerRows, all_part_pairs, near_parts
from trajectotree.config import Config, mu_plan
from trajectotree.geometry import capsule_distances
from trajectotree.planning.physics import check_space_physics
from trajectotree.planning.spatial import object_model
from trajectotree.results import FINGER_OVERLAP_TOL
from trajectotree.scene.spatial import START_POSE, build_space_scene

SAMPLES = 20001  # points along one axis of a brute-force pair (10 um apart at most), each against the other exactly


@pytest.fixture(scope="module")
def hand():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    fingers = space_hand.space_fingers(scene)
    return scene, fingers, mu_plan(config.scene, config.search)


def _close_joints(scene, fingers, seed: int, knots: int) -> np.ndarray:
    """(knots, 4, 3) joint angles within the limits at which two fingers' parts come within -8..10 mm of each
    other (overlapping or close: where the rows bind), drawn from uniform samples."""
    lower, upper = (np.array([getattr(c, name) for c in scene.fingers]) for name in ("q_lower", "q_upper"))
    q = np.random.default_rng(seed).uniform(lower, upper, (4000, 4, 3))
    chain = space_hand.stacked(fingers)
    parts = FingerParts.of(chain, scene.tip_radius)
    _, _, tip, _, link_ends = chain.chain(q)
    least = SpaceFingerRows(parts, all_part_pairs(4, len(parts.radius))).values(tip, link_ends).min(axis=1)
    chosen = q[(least > -0.008) & (least < 0.01)][:knots]
    assert len(chosen) == knots
    return chosen


def _point_segment(p, a, b):
    """(...) the exact distances of points p (..., 3) from the segment a -> b (projection, clamped)."""
    e = b - a
    ee = float(e @ e)
    along = np.sum((p - a) * e, -1)
    s = np.clip(along / ee, 0.0, 1.0) if ee > 0 else np.zeros(along.shape)
    return np.linalg.norm(p - a - s[..., None] * e, axis=-1)


def _brute(A, B, ra, rb):
    """The capsules' signed distance by sampling A's axis, each sample against B's axis exactly."""
    u = np.linspace(0.0, 1.0, SAMPLES)[:, None]
    points = A[0] + u * (A[1] - A[0])
    return _point_segment(points, B[0], B[1]).min() - ra - rb


def test_nearest_points_of_segments_against_sampling():
    rng = np.random.default_rng(0)
    worst = 0.0
    for k in range(200):
        a0, a1, b0, b1 = rng.normal(size=(4, 3)) * 0.05
        if k % 4 == 1:
            a1 = a0.copy()  # a point: a fingertip sphere's axis
        if k % 4 == 2:
            b1 = b0 + 0.6 * (a1 - a0)  # parallel
        mine = capsule_distances(a0, a1, 0.01, b0, b1, 0.008)
        brute = _brute(np.array([a0, a1]), np.array([b0, b1]), 0.01, 0.008)
        assert mine <= brute + 1e-12  # sampling finds no nearer pair
        worst = max(worst, brute - mine)
    assert worst < 1e-6  # m: the samples miss the nearest point by less than half their spacing


def test_rows_against_the_plants_capsules(hand):
    scene, fingers, _ = hand
    q = _close_joints(scene, fingers, 1, 6)
    chain = space_hand.stacked(fingers)
    _, _, tip, _, link_ends = chain.chain(q)
    parts = FingerParts.of(chain, scene.tip_radius)
    pairs = all_part_pairs(4, len(parts.radius))
    rows = SpaceFingerRows(parts, pairs).values(tip, link_ends)
    poses = np.tile(START_POSE, (len(q), 1))
    ends = scene.link_ends_W(poses, q.reshape(len(q), -1))  # the plant's kinematics, (K, F, L, 2, 3)
    tips = np.array([[scene.fingers[f].fingertip(q[k, f]) for f in range(4)] for k in range(len(q))])
    radii = [c.radius for c in scene.link_capsules()[0]] + [scene.tip_radius]
    shapes = np.concatenate([ends, np.repeat(tips[:, :, None, None], 2, axis=3)], axis=2)
    brute = np.array(
        [[_brute(shapes[k, a, i], shapes[k, b, j], radii[i], radii[j]) for a, i, b, j in pairs] for k in range(len(q))]
    )
    assert np.all(rows <= brute + 1e-12) and np.abs(rows - brute).max() < 1e-6
    assert rows.min() < 0.0 < rows.max()  # the test meets overlapping parts and apart ones
    near = near_parts(parts, parts.ends(tip, link_ends), 0.02)
    assert 0 < len(near) < len(pairs)
    assert {tuple(p) for p in near} == {tuple(p) for p, d in zip(pairs.tolist(), rows.min(0)) if d < 0.02}


def test_row_gradients_against_central_differences(hand):
    scene, fingers, _ = hand
    chain = space_hand.stacked(fingers)
    parts = FingerParts.of(chain, scene.tip_radius)
    q = _close_joints(scene, fingers, 2, 4)
    rows = SpaceFingerRows(parts, all_part_pairs(4, len(parts.radius)))
    points, axes, tip, _, link_ends = chain.chain(q)
    values, d_a, d_b = rows.jacobians(points, axes, tip, link_ends)
    assert values.min() < 0.005  # m: some parts close, where the rows bind
    step, a, b = 1e-7, rows.pairs[:, 0], rows.pairs[:, 2]
    for finger in range(4):
        for joint in range(3):
            dq = np.zeros_like(q)
            dq[:, finger, joint] = step
            plus, minus = (rows.values(*chain.chain(q + s * dq)[2::2]) for s in (1, -1))
            numeric = (plus - minus) / (2 * step)
            analytic = np.where(a == finger, d_a[..., joint], 0.0) + np.where(b == finger, d_b[..., joint], 0.0)
            assert np.abs(numeric - analytic).max() < 1e-6
    assert np.abs(d_a).max() > 0.01  # m/rad: the rows move with the joints


def test_segment_constraint_jacobian_with_every_pair(hand):
    """The rows scattered into a segment's constraint (mask and columns) against central differences, with the
    link rows before them."""
    scene, fingers, mu = hand
    q = _close_joints(scene, fingers, 3, 1)[0]
    normals = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]])
    p_BC = 0.0325 * normals
    spec = sp.SegmentSpec(np.eye(3), np.eye(3), np.zeros(3), q, q, p_BC, p_BC, normals, normals, None)
    pairs = all_part_pairs(4, 4)
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, 3, sp.SPACE_DT, True, pairs)
    layout = rows.layout
    Z = np.zeros((rows.K, layout.width))
    Z[:, layout.slice("q")] = q.ravel()
    Z = Z + 1e-2 * np.random.default_rng(4).standard_normal(Z.shape)
    J, _, pattern = jacobian_against_differences(sp.SegmentConstraint(rows), Z)
    assert not np.any(J[~pattern])
    lower, _ = rows.knot_bounds()
    apart = slice(rows.apart_row, rows.apart_row + len(pairs))
    assert np.all(np.isinf(lower[[0, -1], apart])) and np.all(lower[1:-1, apart] <= CLEARANCE)


def test_the_check_refuses_fingers_inside_each_other(hand):
    """A still hand whose fourth fingertip sits 5 mm from the first's at the middle knot (its sphere 15 mm
    inside the other's): the check in space names the two fingers, the depth and the knot."""
    scene, fingers, mu = hand
    q = np.tile(np.array([0.0, 0.6, -1.4]), (3, 4, 1))
    _, _, tip, _, link_ends = space_hand.stacked(fingers).chain(q)
    f_W = np.zeros((3, 4, 3))
    arrays = {
        "t": np.array([0.0, 0.5, 1.0]),
        "x": np.tile(START_POSE, (3, 1)),
        "v": np.zeros((3, 6)),
        "q": q.reshape(3, -1),
        "tau": np.zeros((3, 12)),
        "f_W": f_W,
        "p_W_C": tip.copy(),
        "p_W_tip": tip.copy(),
        "p_W_links": link_ends,
    }
    model = object_model(scene)
    apart = check_space_physics(arrays, model, mu)
    assert apart.finger_distance_m > 0.0 and "overlap" not in apart.reason
    arrays["p_W_tip"][1, 3] = arrays["p_W_C"][1, 3] = tip[1, 0] + np.array([0.0, 0.0, -0.005])
    check = check_space_physics(arrays, model, mu)
    assert not check.passed and check.finger_distance_fingers == (0, 3) and check.finger_distance_knot == 1
    assert check.finger_distance_m == pytest.approx(0.005 - 2 * scene.tip_radius, abs=1e-9)
    assert "fingers 0 and 3 overlap by 15.00 mm at knot 1" in check.reason
    assert -check.finger_distance_m > FINGER_OVERLAP_TOL
