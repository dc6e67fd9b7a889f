"""The search on convex polygons: the link-vs-object separating-axis test against a brute-force
check, the box given as a polygon plans the same contacts as the box, and plans on a
triangle (a grasp needs all three faces) hold every node and stance in form closure."""

import math

import numpy as np
import pytest

from trajectotree.config import ObjectConfig, SceneConfig, SearchConfig
from trajectotree.geometry import ConvexPolygon, box_to_world, rotation_2d
from trajectotree.grasp import FormClosure
from trajectotree.reach import Reachability, rectangle_overlaps_box, rectangles_overlap_polygon
from trajectotree.scene import NUM_FINGERS, build_scene
from trajectotree.search import find_contact_plan

TRIANGLE = tuple((0.14 / math.sqrt(3) * math.cos(a), 0.14 / math.sqrt(3) * math.sin(a))
                 for a in np.pi / 2 + 2 * np.pi / 3 * np.arange(3))


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _strictly_inside(p, polygon) -> bool:
    """p inside the counter-clockwise convex polygon (V, 2), not on its boundary."""
    return all(_cross(b - a, p - a) > 0 for a, b in zip(polygon, np.roll(polygon, -1, axis=0)))


def _proper_crossing(p1, p2, q1, q2) -> bool:
    d = [_cross(p2 - p1, q1 - p1), _cross(p2 - p1, q2 - p1), _cross(q2 - q1, p1 - q1), _cross(q2 - q1, p2 - q1)]
    return d[0] * d[1] < 0 and d[2] * d[3] < 0


def brute_force_overlap(a, b) -> bool:
    """Do the interiors of convex polygons a and b (counter-clockwise (V, 2)) intersect? A vertex
    of one strictly inside the other or two edges crossing (exact for general positions)."""
    if any(_strictly_inside(p, b) for p in a) or any(_strictly_inside(p, a) for p in b):
        return True
    return any(_proper_crossing(a[i], a[(i + 1) % len(a)], b[j], b[(j + 1) % len(b)])
               for i in range(len(a)) for j in range(len(b)))


def rectangle_corners(center, angle, hl, hw):
    return np.asarray(center) + np.array([[hl, -hw], [hl, hw], [-hl, hw], [-hl, -hw]]) @ rotation_2d(angle).T


def random_polygon(rng) -> ConvexPolygon:
    """Points on a random ellipse (a convex polygon), 3 to 8 of them."""
    angles = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(3, 9)))
    stretch = rotation_2d(rng.uniform(0, np.pi)) @ np.diag(rng.uniform(0.03, 0.12, 2))
    return ConvexPolygon.from_points(np.stack([np.cos(angles), np.sin(angles)], 1) @ stretch.T)


def test_separating_axis_test_matches_brute_force():
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(150):
        polygon = random_polygon(rng)
        centers = rng.uniform(-0.2, 0.2, (20, 2))
        angles = rng.uniform(-np.pi, np.pi, 20)
        hl, hw = rng.uniform(0.005, 0.08, 2)
        sat = rectangles_overlap_polygon(polygon, centers, angles, hl, hw)
        brute = [brute_force_overlap(rectangle_corners(c, g, hl, hw), polygon.vertices) for c, g in zip(centers, angles)]
        np.testing.assert_array_equal(sat, brute)
        hits += int(np.sum(sat))
    assert 300 < hits < 2700  # both outcomes are well represented


def test_box_keeps_its_closed_form_and_the_generic_test_agrees():
    rng = np.random.default_rng(4)
    box = ConvexPolygon.box(0.2, 0.1)
    generic = ConvexPolygon(box.vertices)  # the same outline without the box's closed forms
    assert box.is_box and not generic.is_box
    centers, angles = rng.uniform(-0.2, 0.2, (2000, 2)), rng.uniform(-np.pi, np.pi, 2000)
    closed = rectangles_overlap_polygon(box, centers, angles, 0.05, 0.01)
    np.testing.assert_array_equal(closed, [rectangle_overlaps_box(c, g, 0.05, 0.01, 0.1, 0.05) for c, g in zip(centers, angles)])
    np.testing.assert_array_equal(closed, rectangles_overlap_polygon(generic, centers, angles, 0.05, 0.01))
    # touching is not overlapping: a rectangle flush against the right face (sizes exact in binary)
    square = ConvexPolygon.from_points([[0.125, -0.125], [0.125, 0.125], [-0.125, 0.125], [-0.125, -0.125]])
    triangle = ConvexPolygon.from_points([[0.125, -0.125], [0.125, 0.125], [-0.25, 0.0]])  # centroid at 0
    for polygon in (square, triangle):
        assert not rectangles_overlap_polygon(polygon, [[0.1875, 0.0]], [0.0], 0.0625, 0.03125)[0]
        assert rectangles_overlap_polygon(polygon, [[0.1870, 0.0]], [0.0], 0.0625, 0.03125)[0]
