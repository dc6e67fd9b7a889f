"""Box boundary parameterization and signed distance."""

import numpy as np
import pytest

from trajectotree.geometry import ConvexPolygon, box_to_world, world_to_box

BOX = ConvexPolygon.box(0.20, 0.10)


def test_perimeter_and_corners():
    assert BOX.perimeter == pytest.approx(0.6)
    for s, corner in zip(BOX.corner_arclengths(), [(0.1, -0.05), (0.1, 0.05), (-0.1, 0.05), (-0.1, -0.05)]):
        np.testing.assert_allclose(BOX.point(s)[0], corner, atol=1e-12)


def test_arclength_point_round_trip():
    for s in np.linspace(0.001, BOX.perimeter - 0.001, 97):
        p, _ = BOX.point(s)
        assert BOX.arclength(p) == pytest.approx(s, abs=1e-12)
        assert BOX.signed_distance(p) == pytest.approx(0.0, abs=1e-12)
    assert BOX.point(0.05 + BOX.perimeter)[0] == pytest.approx(BOX.point(0.05)[0])  # wraps


def test_normals_are_unit_and_outward():
    for s in np.linspace(0.005, BOX.perimeter - 0.005, 60):
        if BOX.corner_distance(s) < 1e-3:
            continue
        p, n = BOX.point(s)
        assert np.linalg.norm(n) == pytest.approx(1.0)
        assert BOX.signed_distance(p + 1e-3 * n) == pytest.approx(1e-3)
        assert BOX.signed_distance(p - 1e-3 * n) == pytest.approx(-1e-3)
        t = BOX.tangent(s)  # counter-clockwise: moving along t increases s
        assert BOX.arclength(p + 1e-4 * t) == pytest.approx(s + 1e-4, abs=1e-9)


def test_signed_distance_cases():
    assert BOX.signed_distance([0, 0]) == pytest.approx(-0.05)
    assert BOX.signed_distance([0.05, 0.0]) == pytest.approx(-0.05)
    assert BOX.signed_distance([0.09, 0.0]) == pytest.approx(-0.01)
    assert BOX.signed_distance([0.13, 0.0]) == pytest.approx(0.03)
    assert BOX.signed_distance([0.0, 0.08]) == pytest.approx(0.03)
    assert BOX.signed_distance([0.13, 0.09]) == pytest.approx(0.05)  # 3-4-5 from the corner
    assert BOX.signed_distance([0.1, 0.0]) == pytest.approx(0.0)


def test_corner_distance():
    assert BOX.corner_distance(0.0) == 0.0
    assert BOX.corner_distance(0.02) == pytest.approx(0.02)
    assert BOX.corner_distance(0.59) == pytest.approx(0.01)
    assert BOX.corner_distance(0.2) == pytest.approx(0.1)  # middle of the top face


def test_pose_transforms_round_trip():
    pose = (0.02, -0.01, 0.7)
    p_B = np.array([0.05, 0.03])
    np.testing.assert_allclose(world_to_box(pose, box_to_world(pose, p_B)), p_B)
    np.testing.assert_allclose(box_to_world((0, 0, np.pi / 2), [1.0, 0.0]), [0.0, 1.0], atol=1e-12)
