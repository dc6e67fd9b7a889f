"""The object boundary (the box and convex polygons): parameterization, signed distance, inertia."""

import numpy as np
import pytest

from trajectotree.geometry import (
    SMOOTH_EDGE,
    ConvexPolygon,
    box_to_world,
    ellipse_points,
    polygon_problem,
    world_to_box,
)

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


# ---- convex polygons ----------------------------------------------------------------------


def regular(n: int, radius: float, phase: float = 0.0) -> np.ndarray:
    angles = phase + 2 * np.pi * np.arange(n) / n
    return radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


TRIANGLE = ConvexPolygon.from_points([[0.0, 0.0], [0.14, 0.0], [0.07, 0.07 * np.sqrt(3)]])
HEXAGON = ConvexPolygon.from_points(regular(6, 0.07))


def test_polygon_closed_forms():
    side = 0.14
    assert TRIANGLE.perimeter == pytest.approx(3 * side)
    assert TRIANGLE.area == pytest.approx(np.sqrt(3) / 4 * side**2)
    np.testing.assert_allclose(TRIANGLE.vertices.mean(axis=0), 0.0, atol=1e-15)  # re-centred
    assert TRIANGLE.inertia(2.0) == pytest.approx(2.0 * side**2 / 12)  # uniform triangle
    assert HEXAGON.perimeter == pytest.approx(6 * 0.07)
    assert HEXAGON.inertia(1.0) == pytest.approx(5 / 12 * 0.07**2)  # regular hexagon
    for shape in (TRIANGLE, HEXAGON):
        np.testing.assert_allclose(np.linalg.norm(shape.normals, axis=1), 1.0)
        np.testing.assert_allclose(np.einsum("fa,fa->f", shape.normals, shape.directions), 0.0, atol=1e-15)
        # outward: the centroid is on the inner side of every face, by the inradius for regular shapes
        np.testing.assert_allclose(shape.offsets, shape.offsets[0])
        assert shape.signed_distance([0.0, 0.0]) == pytest.approx(-shape.offsets[0])


def test_square_plate_is_the_box():
    square = ConvexPolygon(ConvexPolygon.box(0.1, 0.1).vertices)  # the generic formulas, no closed forms
    assert not square.is_box
    assert square.inertia(0.05) == pytest.approx(ConvexPolygon.box(0.1, 0.1).inertia(0.05), rel=1e-14)
    assert square.inertia(0.05) == pytest.approx(0.05 * 0.02 / 12, rel=1e-14)
    p = np.random.default_rng(1).uniform(-0.15, 0.15, (500, 2))
    box = ConvexPolygon.box(0.1, 0.1)
    np.testing.assert_allclose(square.signed_distances(p), box.signed_distances(p), atol=1e-15)
    np.testing.assert_allclose(square.nearest_points(p), box.nearest_points(p), atol=1e-15)


def test_polygon_signed_distance_cases():
    r = 0.07 * np.sqrt(3) / 2  # hexagon inradius
    assert HEXAGON.signed_distance([0.0, 0.0]) == pytest.approx(-r)
    n = HEXAGON.normals[0]
    assert HEXAGON.signed_distance((r + 0.01) * n) == pytest.approx(0.01)  # off a face
    v = HEXAGON.vertices[2]
    assert HEXAGON.signed_distance(1.5 * v) == pytest.approx(0.5 * 0.07)  # off a vertex
    for s in np.linspace(0.0, HEXAGON.perimeter, 50, endpoint=False):
        p, _ = HEXAGON.point(s)
        assert HEXAGON.signed_distance(p) == pytest.approx(0.0, abs=1e-15)
        assert HEXAGON.arclength(p) == pytest.approx(s, abs=1e-12)
        if HEXAGON.corner_distance(s) > 0.004:  # pushed out along the face normal, projected back
            np.testing.assert_allclose(HEXAGON.project(p + 0.003 * HEXAGON.face_normals(p[None])[0]), p, atol=1e-12)


def test_points_follow_the_boundary_counter_clockwise():
    for shape in (TRIANGLE, HEXAGON):
        s = np.linspace(0.0, shape.perimeter, 200, endpoint=False)
        p, n = shape.points(s)
        for k in range(0, 200, 17):
            q, m = shape.point(s[k])
            np.testing.assert_allclose(p[k], q, atol=1e-15)
            np.testing.assert_allclose(n[k], m)
        # counter-clockwise: the outward normal is the tangent turned clockwise
        t = np.array([shape.tangent(x) for x in s[::23]])
        np.testing.assert_allclose(np.stack([t[:, 1], -t[:, 0]], axis=1), n[::23], atol=1e-15)


def test_vertex_order_and_start():
    """Either orientation and any first vertex: the same polygon, started at its right face."""
    box = ConvexPolygon.box(0.2, 0.1)
    clockwise = [[-0.1, 0.05], [0.1, 0.05], [0.1, -0.05], [-0.1, -0.05]]
    again = ConvexPolygon.from_points(clockwise)
    assert again.is_box
    np.testing.assert_array_equal(again.vertices, box.vertices)
    shifted = ConvexPolygon.from_points(np.array(clockwise) + [0.3, -0.2])  # re-centred
    np.testing.assert_allclose(shifted.vertices, box.vertices, atol=1e-15)
    np.testing.assert_allclose(
        ConvexPolygon.from_points(TRIANGLE.vertices[::-1]).vertices, TRIANGLE.vertices, atol=1e-15
    )


@pytest.mark.parametrize(
    "points, problem",
    [
        ([[0, 0], [1, 0]], "at least 3 vertices"),
        ([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.2]], "not convex"),
        ([[0, 0], [1, 1], [1, 0], [0, 1]], "self-intersecting"),
        ([[0, 0], [1, 0], [1, 0], [0, 1]], "repeat"),
        ([[0, 0], [1, 0], [2, 0], [1, 1]], "collinear"),
        (regular(5, 0.07)[[0, 2, 4, 1, 3]], "self-intersecting"),  # a pentagram
    ],
)
def test_bad_polygons_are_named(points, problem):
    assert problem in polygon_problem(points)
    with pytest.raises(ValueError, match=problem):
        ConvexPolygon.from_points(points)


def test_penetration_depth_closed_forms_and_the_search_overlap_test():
    from trajectotree.search.reach import rectangles_overlap_polygon

    def square(cx, cy, h):
        return np.array([[cx - h, cy - h], [cx + h, cy - h], [cx + h, cy + h], [cx - h, cy + h]])

    box = ConvexPolygon.box(0.2, 0.1)
    depths = box.penetration_depths(
        np.stack([square(0.104, 0.0, 0.01), square(0.2, 0.0, 0.01), square(0.0, 0.0, 0.01)])
    )
    np.testing.assert_allclose(depths, [0.006, 0.0, 0.06], atol=1e-15)  # centred: out through the long face
    triangle = ConvexPolygon.from_points([[0, -0.08], [0.07, 0.04], [-0.07, 0.04]])
    assert triangle.penetration_depths(square(0.0, 0.045, 0.01)) == pytest.approx(0.005)
    # overlap iff depth > 0, as the search's separating-axis test says, on random rectangles
    rng = np.random.default_rng(1)
    centres, angles = rng.uniform(-0.15, 0.15, (500, 2)), rng.uniform(-np.pi, np.pi, 500)
    hl, hw = 0.04, 0.005
    local = np.array([[hl, -hw], [hl, hw], [-hl, hw], [-hl, -hw]])
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    corners = centres[:, None] + np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]], -1)
    for shape in (box, triangle):
        overlap = rectangles_overlap_polygon(shape, centres, angles, hl, hw)
        depth = shape.penetration_depths(corners)
        assert 50 < overlap.sum() < 450 and np.array_equal(depth > 1e-12, overlap)


def regular_polygon(n: int, circumradius: float) -> ConvexPolygon:
    angles = 2 * np.pi * (np.arange(n) + 0.5) / n
    return ConvexPolygon.from_points(np.stack([np.cos(angles), np.sin(angles)], axis=1) * circumradius)


def test_corner_margins_follow_the_corner_angle_in_closed_form():
    np.testing.assert_array_equal(BOX.corner_margins(0.015), 0.015)  # the box's right angles keep the full margin
    for n in (5, 6, 12, 40):  # exterior angle 2 pi / n: margin tan(pi / n) at most
        np.testing.assert_allclose(regular_polygon(n, 0.07).corner_margins(0.015), 0.015 * min(1, np.tan(np.pi / n)))
    np.testing.assert_array_equal(regular_polygon(3, 0.08).corner_margins(0.015), 0.015)  # sharper: capped
    # the 12-gon of circumradius 0.065 m (edges 33.6 mm) keeps 4.0 mm at each corner, 25.6 mm of each edge free
    gon = regular_polygon(12, 0.065)
    s = np.linspace(0.0, gon.perimeter, 20001)[:-1]
    free = gon.corner_free(s, 0.015)
    assert free.mean() == pytest.approx(1 - 2 * 0.015 * np.tan(np.pi / 12) / gon.edge_lengths[0], abs=1e-3)
    np.testing.assert_array_equal(
        BOX.corner_free([0.0, 0.0149, 0.015, 0.05, 0.085, 0.0851], 0.015), [False, False, True, True, True, False]
    )


def test_sides_join_faces_across_blunt_vertices_only():
    assert set(BOX.sides(np.linspace(0, 0.6, 61)[:-1])) == {0, 1, 2, 3}
    assert BOX.sides([0.01])[0] != BOX.sides([0.11])[0]  # across the corner at 0.1 m
    disc = ConvexPolygon.from_points(ellipse_points(0.06, 0.06))
    assert set(disc.sides(np.linspace(0, disc.perimeter, 100))) == {0}  # no corner at all
    assert len(set(regular_polygon(12, 0.065).sides(np.linspace(0, 0.4, 400)))) == 12  # 30 deg: corners


@pytest.mark.parametrize("semi_x, semi_y", [(0.06, 0.06), (0.08, 0.05)])
def test_polygonized_round_shapes_against_their_closed_forms(semi_x, semi_y):
    points = ellipse_points(semi_x, semi_y)
    n = len(points)
    assert n % 4 == 0 and polygon_problem(points) is None
    shape = ConvexPolygon.from_points(points, smooth=True)
    assert shape.edge_lengths.max() <= SMOOTH_EDGE
    np.testing.assert_allclose(shape.vertices.mean(axis=0), 0.0, atol=1e-12)  # symmetric about its centre
    np.testing.assert_allclose(shape.normals[0], [1.0, 0.0], atol=1e-12)  # a face centred on +x, as the box
    np.testing.assert_allclose((shape.vertices[:, 0] / semi_x) ** 2 + (shape.vertices[:, 1] / semi_y) ** 2, 1.0)
    if semi_x == semi_y:  # the disc: every contact within r (1 - cos(pi / n)) of the circle, its normal radial
        p, normal = shape.points(np.linspace(0.0, shape.perimeter, 997))
        r = np.linalg.norm(p, axis=1)
        assert np.all(r <= semi_x + 1e-12) and np.all(r >= semi_x * np.cos(np.pi / n) - 1e-12)
        radial = np.arccos(np.clip(np.einsum("ka,ka->k", normal, p / r[:, None]), -1, 1))
        assert radial.max() <= 1e-6  # smooth normals: the circle's own, not the facets' (off by up to pi / n)
        assert not ConvexPolygon.from_points(points).smooth and shape.smooth
        assert shape.area == pytest.approx(n / 2 * semi_x**2 * np.sin(2 * np.pi / n), rel=1e-12)
        assert shape.perimeter == pytest.approx(2 * np.pi * semi_x, rel=2 * (np.pi / n) ** 2 / 6)
