"""The search on convex polygons: the link-vs-object separating-axis test against a brute-force
check, the box given as a polygon plans the same contacts as the box, and plans on a
triangle (a grasp needs all three faces) hold every node and stance in form closure."""

import math
from dataclasses import replace

import numpy as np
import pytest

from trajectotree.config import ConfigError, GoalPose, ObjectConfig, SceneConfig, SearchConfig, segments_for
from trajectotree.geometry import ConvexPolygon, box_to_world, rotation_2d
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.grasp import FormClosure
from trajectotree.search.reach import Reachability, rectangles_overlap_polygon
from trajectotree.search.tree import find_contact_plan, grid_levels

TRIANGLE = tuple(
    (0.14 / math.sqrt(3) * math.cos(a), 0.14 / math.sqrt(3) * math.sin(a))
    for a in np.pi / 2 + 2 * np.pi / 3 * np.arange(3)
)


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
    return any(
        _proper_crossing(a[i], a[(i + 1) % len(a)], b[j], b[(j + 1) % len(b)])
        for i in range(len(a))
        for j in range(len(b))
    )


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
    for _ in range(60):
        polygon = random_polygon(rng)
        centers = rng.uniform(-0.2, 0.2, (20, 2))
        angles = rng.uniform(-np.pi, np.pi, 20)
        hl, hw = rng.uniform(0.005, 0.08, 2)
        sat = rectangles_overlap_polygon(polygon, centers, angles, hl, hw)
        brute = [
            brute_force_overlap(rectangle_corners(c, g, hl, hw), polygon.vertices) for c, g in zip(centers, angles)
        ]
        np.testing.assert_array_equal(sat, brute)
        hits += int(np.sum(sat))
    assert 120 < hits < 1080  # both outcomes are well represented


def test_box_keeps_its_closed_form_and_the_generic_test_agrees():
    rng = np.random.default_rng(4)
    box = ConvexPolygon.box(0.2, 0.1)
    generic = ConvexPolygon(box.vertices)  # the same outline without the box's closed forms
    assert box.is_box and not generic.is_box
    centers, angles = rng.uniform(-0.2, 0.2, (2000, 2)), rng.uniform(-np.pi, np.pi, 2000)
    closed = rectangles_overlap_polygon(box, centers, angles, 0.05, 0.01)
    brute = [
        brute_force_overlap(rectangle_corners(c, g, 0.05, 0.01), box.vertices)
        for c, g in zip(centers[:400], angles[:400])
    ]
    np.testing.assert_array_equal(closed[:400], brute)
    np.testing.assert_array_equal(closed, rectangles_overlap_polygon(generic, centers, angles, 0.05, 0.01))
    # touching is not overlapping: a rectangle flush against the right face (sizes exact in binary)
    square = ConvexPolygon.from_points([[0.125, -0.125], [0.125, 0.125], [-0.125, 0.125], [-0.125, -0.125]])
    triangle = ConvexPolygon.from_points([[0.125, -0.125], [0.125, 0.125], [-0.25, 0.0]])  # centroid at 0
    for polygon in (square, triangle):
        assert not rectangles_overlap_polygon(polygon, [[0.1875, 0.0]], [0.0], 0.0625, 0.03125)[0]
        assert rectangles_overlap_polygon(polygon, [[0.1870, 0.0]], [0.0], 0.0625, 0.03125)[0]


@pytest.fixture(scope="module")
def triangle_scene():
    return build_scene(SceneConfig(object=ObjectConfig(vertices=TRIANGLE)))


def test_the_box_given_as_a_polygon_plans_the_same_contacts():
    # clockwise, starting at the top-left corner: re-ordered into the box (vertex 0 at (w/2, -h/2))
    clockwise = ((-0.1, 0.05), (0.1, 0.05), (0.1, -0.05), (-0.1, -0.05))
    polygon_scene = build_scene(SceneConfig(object=ObjectConfig(vertices=clockwise)))
    assert polygon_scene.config.shape.is_box
    np.testing.assert_array_equal(polygon_scene.config.shape.vertices, ConvexPolygon.box(0.2, 0.1).vertices)
    a, b = (find_contact_plan(s, -1.2, SearchConfig()) for s in (build_scene(), polygon_scene))
    assert a.success and b.success
    for m, n in zip(a.nodes, b.nodes, strict=True):
        np.testing.assert_array_equal(m.arclengths, n.arclengths)
        np.testing.assert_array_equal(m.q, n.q)
        assert m.switching_finger == n.switching_finger


def check_polygon_plan(scene, plan, config: SearchConfig):
    """Every node and every three-finger stance of `plan` checked independently of the search:
    a fresh LP at mu_plan, the plant's kinematics, and a brute-force link-vs-object overlap test."""
    shape, mu = scene.config.shape, config.friction_safety * scene.config.mu
    closure, reach = FormClosure(shape, mu, config.min_closure_margin), Reachability(scene)
    assert plan.success, plan.reason
    assert len(plan.nodes) == segments_for(config, scene.config.initial_pose, GoalPose(plan.goal)) + 1
    np.testing.assert_allclose(plan.object_path[-1], np.add(scene.config.initial_pose, (0, 0, plan.goal)))
    for n, node in enumerate(plan.nodes):
        assert closure.check(node.arclengths).in_closure
        p_WF = scene.fingertip_positions(node.q)
        for i in range(NUM_FINGERS):
            assert shape.corner_free([node.arclengths[i] + 1e-12], scene.config.corner_margin)[0]
            assert shape.signed_distance(node.p_BC[i]) == pytest.approx(0.0, abs=1e-12)
            target = (
                box_to_world(node.object_pose, node.p_BC[i])
                + scene.tip_radius * rotation_2d(node.object_pose[2]) @ node.n_B[i]
            )
            np.testing.assert_allclose(p_WF[i], target, atol=1e-5)
            q, f = node.q[2 * i : 2 * i + 2], scene.fingers[i]
            assert np.all(q >= f.q_lower - 1e-7) and np.all(q <= f.q_upper + 1e-7)
            outline = np.array([box_to_world(node.object_pose, v) for v in shape.vertices])
            assert not any(brute_force_overlap(link, outline) for link in reach.link_polygons(i, q))
        if n:
            moved = [i for i in range(NUM_FINGERS) if node.arclengths[i] != plan.nodes[n - 1].arclengths[i]]
            assert moved == ([] if node.switching_finger is None else [node.switching_finger])
            if moved:  # the other three held the object while the finger moved
                assert closure.check(np.delete(plan.nodes[n - 1].arclengths, moved)).in_closure


def test_triangle_plans_hold_every_stance_in_closure(triangle_scene):
    # A grasp of the triangle needs all three faces; at mu_plan 0.49 the large turn -3.124 has no plan on the
    # 0.02 m contact grid from its best 200 initial grasps (no grid point at a face's middle; the next test
    # searches it alone), nor, with the fingers kept 2 mm apart, on the refined 0.01 m grid. -2.0 has one
    # from the refined grid's first root (the grids take turns, one root each: contacts off the coarse grid
    # mean the coarse grid's first root had none).
    config = SearchConfig()
    for goal in (0.86, -2.0):
        plan = find_contact_plan(triangle_scene, goal, config)
        check_polygon_plan(triangle_scene, plan, config)
    s = np.array([n.arclengths for n in plan.nodes])
    assert np.any(np.abs(s - 0.02 * np.round(s / 0.02)) > 1e-6)  # contacts off the coarse grid


@pytest.mark.slow  # the coarse grid's 200 initial grasps searched again, alone (a second or more)
def test_the_large_turn_of_the_triangle_has_no_plan_on_the_coarse_grid(triangle_scene):
    coarse = find_contact_plan(triangle_scene, -3.124, replace(SearchConfig(), grid_refinements=0))
    assert not coarse.success and "no plan from" in coarse.reason
    assert coarse.stats.initial_grasps_searched == 200


def test_grid_levels_and_their_bad_input():
    coarse, fine = grid_levels(SearchConfig())
    assert (coarse.displacement_step, coarse.num_displacements, coarse.initial_grid_step) == (0.02, 17, 0.02)
    assert (fine.displacement_step, fine.num_displacements, fine.initial_grid_step) == (0.01, 33, 0.01)
    assert grid_levels(SearchConfig(grid_refinements=0)) == [SearchConfig(grid_refinements=0)]
    for bad in (
        dict(grid_refinements=4),
        dict(grid_refinements=-1),
        dict(grid_refinements=1.0),
        dict(num_displacements=101, grid_refinements=2),
        dict(initial_grid_step=0.003, grid_refinements=2),
    ):
        with pytest.raises(ConfigError, match="search.grid_refinements"):
            SearchConfig(**bad)


def test_link_collision_test_matches_scene_graph_on_a_polygon(triangle_scene):
    # the plant's object is the triangle's prism: SceneGraph's signed distances are the reference
    from test_reach import check_link_collisions_against_scene_graph

    check_link_collisions_against_scene_graph(triangle_scene, Reachability(triangle_scene), seed=7, min_each=10)


def test_vectorized_closed_form_matches_the_scalar_one_on_a_polygon(triangle_scene):
    reach, rng = Reachability(triangle_scene), np.random.default_rng(5)
    reachable = 0
    for _ in range(30):
        pose = (rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), rng.uniform(-np.pi, np.pi))
        finger = int(rng.integers(NUM_FINGERS))
        arclengths = rng.uniform(0, reach.boundary.perimeter, 40)
        for s, q in zip(arclengths, reach.closed_form_many(pose, finger, arclengths)):
            scalar = reach.closed_form(pose, finger, s)
            assert scalar.reachable == bool(np.isfinite(q[0]))
            if scalar.reachable:
                np.testing.assert_allclose(q, scalar.q, atol=1e-6)
                reachable += 1
    assert reachable > 50
