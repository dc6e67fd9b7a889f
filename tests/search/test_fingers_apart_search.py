"""The search with the fingers kept apart, at its speed: the contact grids taking turns (goal
3.124 rad, which the 0.02 m grid cannot serve with the fingertips apart, plans from the 0.01 m
grid's first root after the coarse grid's first), the initial grasps' finger filter (one test per
distinct pair of contacts) against the all-pairs test, touching fingertips admitted by a clearance
of 0 up to rounding and by no more, and a node's finger test in one pass with its path's."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from trajectotree.config import Config, with_segments
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.results import check_goal
from trajectotree.scene.finger_clearance import (
    DISTANCE_ROUNDING,
    interpolate_joints,
    pair_distances,
    pair_lower_bounds,
)
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import fingers_apart, grasp_joints, grid_contacts
from trajectotree.search.reach import Reachability, path_refusal
from trajectotree.search.tree import _Node, _Search, find_contact_plan

TOUCHING = (0.52, 0.18, 0.2, 0.5)  # fingertips 0 and 3, 1 and 2 on grid contacts 2 r = 20 mm apart
APART = (0.06, 0.2, 0.34, 0.5)  # the best-ranked initial grasp, every finger apart


@pytest.fixture(scope="module")
def scene():
    return build_scene(Config().scene)


def search_at(scene, goal: float, clearance: float) -> _Search:
    goal = check_goal(goal)
    config = replace(Config().search, finger_clearance=clearance)
    return _Search(scene, goal, with_segments(config, scene.config.initial_pose, goal))


@pytest.mark.slow  # two roots' searches on two grids, the fine one's table: 3-6 s
def test_a_goal_the_coarse_grid_cannot_serve_plans_from_the_fine_grids_first_root(scene):
    # On the 0.02 m grid two fingertips on one face are 20 mm (touching) or 40 mm apart; this turn needs
    # them 30 mm apart, on the 0.01 m grid, whose first root the search tries after the coarse grid's first
    # (before the grids took turns: after the coarse grid's 200, 2002 expansions).
    plan = find_contact_plan(scene, 3.124, Config().search)
    assert plan.success
    assert plan.stats.initial_grasps_searched == 2
    s = np.array([n.arclengths for n in plan.nodes])
    assert np.any(np.abs(s - 0.02 * np.round(s / 0.02)) > 1e-6)  # contacts off the coarse grid
    q = np.array([n.q for n in plan.nodes])
    knots = pair_distances(scene.fingers, q, scene.tip_radius)
    assert min(float(d.min()) for d in knots.values()) >= 0.002 - DISTANCE_ROUNDING
    between = pair_distances(scene.fingers, interpolate_joints(q, 20), scene.tip_radius)
    assert min(float(d.min()) for d in between.values()) > 0.0


@pytest.mark.parametrize("clearance", [0.0, 0.002])
def test_the_initial_grasps_finger_filter_is_the_all_pairs_test(scene, clearance):
    reach = Reachability(scene)
    grasps = np.array(list(itertools.product(*grid_contacts(scene, 0.02, reach))))
    distances = pair_distances(scene.fingers, grasp_joints(scene, reach, grasps), scene.tip_radius)
    every_pair = np.all([d >= clearance - DISTANCE_ROUNDING for d in distances.values()], axis=0)
    assert 0 < every_pair.sum() < len(grasps)
    assert np.array_equal(fingers_apart(scene, reach, grasps, clearance), every_pair)


def test_touching_fingertips_pass_a_clearance_of_zero_and_no_more(scene):
    q = grasp_joints(scene, Reachability(scene), np.array([TOUCHING]))
    gaps = pair_distances(scene.fingers, q, scene.tip_radius)
    assert abs(float(gaps[(0, 3)][0])) < DISTANCE_ROUNDING and abs(float(gaps[(1, 2)][0])) < DISTANCE_ROUNDING
    assert float(gaps[(1, 2)][0]) < 0.0  # rounding: just below 0, which a plain comparison refused
    assert search_at(scene, 0.5, 0.0).unreachable(_Node(0, TOUCHING, None, None)) is None
    refusal = search_at(scene, 0.5, 0.002).unreachable(_Node(0, TOUCHING, None, None))
    assert refusal.kind is RefusalKind.FINGERS_COLLIDE and refusal.fingers in ((0, 3), (1, 2))


def test_a_nodes_finger_test_refuses_the_path_from_its_parent_as_the_path_test_does(scene):
    search, r = search_at(scene, 0.5, 0.002), scene.tip_radius
    root = _Node(0, APART, None, None)
    assert search.unreachable(root) is None
    start = search.joints(root)
    end = start.copy()
    end[2] = 0.5  # finger 1's first joint turned from -0.66 rad: it swings through another finger on the way
    expected = path_refusal(scene.fingers, start, end, r, 0.002)
    assert expected == Refusal(RefusalKind.FINGERS_COLLIDE, fingers=expected.fingers, limit=0.002, count=1)
    assert search.fingers_refused(_Node(1, APART, 1, root), end) == expected
    assert search.fingers_refused(_Node(1, APART, None, root), search.joints(_Node(1, APART, None, root))) is None


def test_the_capsules_bound_never_clears_fingers_the_exact_distance_does_not(scene):
    lower = np.concatenate([f.q_lower for f in scene.fingers])
    upper = np.concatenate([f.q_upper for f in scene.fingers])
    q = np.random.default_rng(2).uniform(lower, upper, (5000, len(lower)))
    pairs = list(itertools.combinations(range(scene.num_fingers), 2))
    exact = pair_distances(scene.fingers, q, scene.tip_radius)
    bound = pair_lower_bounds(scene.fingers, q, scene.tip_radius, pairs)
    exact, bound = np.stack([exact[pair] for pair in pairs]), np.stack([bound[pair] for pair in pairs])
    apart = bound >= 0.0
    assert np.all(exact[apart] >= bound[apart] - 1e-15)
    near = (exact >= 0.0) & (exact < 0.02)  # where it matters, within 20 mm, it is close
    assert near.sum() > 100 and np.median(exact[near] - bound[near]) < 1e-3
