"""Fingers kept apart by the search: the exact planar finger-finger distance against SceneGraph's,
a node with crossing fingers refused with its reason, the initial grasps' fingers apart, and
`scene --figure` drawing the grasp a plan starts from."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from trajectotree.config import Config, with_segments
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.results import check_goal
from trajectotree.scene.finger_clearance import closest_fingers, fingers_clear, pair_distances
from trajectotree.scene.hand import finger_bodies
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import grasp_joints, initial_grasp_candidates
from trajectotree.search.reach import Reachability, path_refusal
from trajectotree.search.tree import _Node, _Search, choose_initial_grasp, find_contact_plan

# Grid grasps (arclengths, m) of the default box: the best-ranked initial grasp before fingers were
# tested against each other (fingertip 0 11.3 mm inside finger 1's link 2, fingertip 2 inside finger
# 3's), the one 50 of the 60 seed-0 plans started from (fingertips 0 and 3, 1 and 2 touching), and
# today's best (every finger apart).
OVERLAPPING = (0.08, 0.02, 0.38, 0.32)
TOUCHING = (0.52, 0.18, 0.2, 0.5)
APART = (0.06, 0.2, 0.34, 0.5)


@pytest.fixture(scope="module")
def scene():
    return build_scene(Config().scene)


def joints(scene, arclengths) -> np.ndarray:
    """(2F,) the closed-form joint angles of a grasp at the initial pose."""
    return grasp_joints(scene, Reachability(scene), np.array([arclengths]))[0]


def drake_distances(scene, q) -> dict[tuple[int, int], float]:
    """{(i, j): the least signed distance SceneGraph finds between any collision geometry of finger
    i and any of finger j} at the hand's joint angles q."""
    plant, graph = scene.plant, scene.scene_graph
    context = scene.diagram.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), scene.hand, q)
    query = graph.get_query_output_port().Eval(graph.GetMyContextFromRoot(context))
    geometries = [
        [g for body in finger_bodies(plant, scene.hand, f) for g in plant.GetCollisionGeometriesForBody(body)]
        for f in scene.hand_description.fingers
    ]
    return {
        (i, j): min(
            query.ComputeSignedDistancePairClosestPoints(a, b).distance
            for a, b in itertools.product(geometries[i], geometries[j])
        )
        for i, j in itertools.combinations(range(scene.num_fingers), 2)
    }


@pytest.mark.parametrize(
    ("grasp", "closest_mm"),
    [(OVERLAPPING, -11.256), (TOUCHING, 0.0), (APART, 100.0)],
    ids=["overlap", "touch", "apart"],
)
def test_the_planar_finger_distance_is_scene_graphs(scene, grasp, closest_mm):
    q = joints(scene, grasp)
    ours = {pair: float(d[0]) for pair, d in pair_distances(scene.fingers, q[None], scene.tip_radius).items()}
    theirs = drake_distances(scene, q)
    assert ours == pytest.approx(theirs, abs=1e-9)
    assert 1e3 * min(ours.values()) == pytest.approx(closest_mm, abs=1e-3)


def test_random_hand_configurations_match_scene_graph_where_the_fingers_are_apart_or_a_tip_sinks(scene):
    rng = np.random.default_rng(1)
    lower = np.concatenate([f.q_lower for f in scene.fingers])
    upper = np.concatenate([f.q_upper for f in scene.fingers])
    checked = 0
    for q in rng.uniform(lower, upper, (40, len(lower))):
        ours = pair_distances(scene.fingers, q[None], scene.tip_radius)
        theirs = drake_distances(scene, q)
        for pair, d in ours.items():
            # two overlapping link boxes: their 3D penetration may be along z (9.6 mm thick), not the plane's
            if d[0] > -0.004:
                assert d[0] == pytest.approx(theirs[pair], abs=1e-9)
                checked += 1
    assert checked > 200


def test_a_node_whose_fingers_cross_is_refused_naming_them(scene):
    goal = check_goal(0.5)
    search = _Search(scene, goal, with_segments(Config().search, scene.config.initial_pose, goal))
    refusal = search.unreachable(_Node(0, OVERLAPPING, None, None))
    assert refusal == Refusal(RefusalKind.FINGERS_COLLIDE, fingers=refusal.fingers, limit=0.002)
    assert refusal.fingers in ((0, 1), (2, 3))
    assert str(refusal) == f"fingers {list(refusal.fingers)} come within 0.002 m of each other"
    assert search.unreachable(_Node(0, APART, None, None)) is None


def test_the_straight_path_between_two_clear_stances_is_tested_too(scene):
    r, clearance = scene.tip_radius, 0.002
    start = joints(scene, APART)
    end = start.copy()
    end[2] = 0.5  # finger 1's first joint turned from -0.66 rad: it swings through another finger on the way
    for q in (start, end):
        assert fingers_clear(closest_fingers(scene.fingers, q[None], r).distance, clearance)
    refusal = path_refusal(scene.fingers, start, end, r, clearance)
    assert refusal == Refusal(RefusalKind.FINGERS_COLLIDE, fingers=refusal.fingers, limit=clearance, count=1)
    assert 1 in refusal.fingers
    assert str(refusal).endswith("on the way from the previous node")
    path = np.linspace(start, end, 500)
    assert min(float(d.min()) for d in pair_distances(scene.fingers, path, r).values()) < clearance
    assert path_refusal(scene.fingers, start, start, r, clearance) is None


def test_every_initial_grasp_keeps_the_fingers_apart(scene):
    search = Config().search
    table = initial_grasp_candidates(scene, search)
    assert len(table) > 100
    distances = pair_distances(scene.fingers, grasp_joints(scene, Reachability(scene), table.arclengths), 0.01)
    assert min(float(d.min()) for d in distances.values()) >= search.finger_clearance
    assert OVERLAPPING not in [c.arclengths for c in table.candidates]
    assert TOUCHING not in [c.arclengths for c in table.candidates]


def test_scene_figure_draws_the_grasp_a_quarter_turns_plan_starts_from(scene, tmp_path, capsys):
    from trajectotree.cli import main

    figure = tmp_path / "scene.png"
    assert main(["scene", "--figure", str(figure), "--json"]) == 0
    reach = json.loads(capsys.readouterr().out)["reach"]
    assert figure.stat().st_size > 0
    plan = find_contact_plan(scene, math.pi / 2, Config().search)
    start = tuple(float(s) for s in plan.nodes[0].arclengths)
    assert reach["start_grasp_goal_rad"] == pytest.approx(math.pi / 2)
    assert tuple(reach["start_grasp_arclengths_m"]) == pytest.approx(start)
    assert choose_initial_grasp(scene, math.pi / 2, Config().search)[0] == pytest.approx(start)
    q = plan.nodes[0].q
    assert min(float(d[0]) for d in pair_distances(scene.fingers, q[None], scene.tip_radius).values()) >= 0.002
