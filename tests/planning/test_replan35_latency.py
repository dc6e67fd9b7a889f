"""Replanning latency (issue 35): a plan from a start (a replan's node state, new friction and mass
estimates) plans on the plant of the scene it is given instead of building one (0.08-0.11 s of a
replan's latency), bit for bit the plan a new plant gives; a replanned plan's later segments are
ready when their own chain is (no joint retry reaches back into them, so none waits for a neighbour's
chain: the mid-way holds of issue 35). Real plans of goal 0.3 rad (2 and 3 segments of 12 knots)."""

import dataclasses
import time

import numpy as np
import pytest

from trajectotree.config import Config, SceneConfig, SearchConfig
from trajectotree.planning.keyframes import solve_first_segment_first, solve_segments
from trajectotree.planning.piece import worker_scene
from trajectotree.planning.planners import plan, plan_request
from trajectotree.planning.request import check_plan_request
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan
from trajectotree.start import StartState

GOAL = 0.3
TWO = Config(search=SearchConfig(num_nodes=3, push_capacity=0.0))  # 2 segments
THREE = Config(search=SearchConfig(num_nodes=4, push_capacity=0.0))  # 3 segments: more than the 2 workers
# max_iter 3: no attempt converges, so every segment runs its whole chain
FAILING = dataclasses.replace(THREE, cito=dataclasses.replace(THREE.cito, max_iter=3))


@pytest.fixture(scope="module")
def scene():
    return build_scene(TWO.scene)


@pytest.fixture(scope="module")
def node_start(scene):
    """The planned state at node 1 of the 2-segment plan (every finger on the object, at rest)."""
    first = plan(goal=GOAL, config=TWO, scene=scene, segment_workers=1)
    assert first.success, first.status
    k = TWO.cito.knots_per_segment
    return StartState(object_pose=tuple(first.trajectory.x[k]), q=tuple(first.trajectory.q[k]))


def estimated(config: Config, mu: float, mass: float) -> Config:
    return dataclasses.replace(config, scene=dataclasses.replace(config.scene, mu=mu, box_mass=mass))


def test_a_start_plans_on_the_plant_of_the_scene_given(scene, node_start):
    config = estimated(TWO, 0.6, 0.055)
    request = check_plan_request(goal=GOAL, config=config, scene=scene, start=node_start)
    assert request.scene.plant is scene.plant  # no plant built
    assert request.scene.config == request.config.scene  # the planners read the start's pose, mu and mass from it
    assert request.scene.config.initial_pose == node_start.object_pose and request.scene.config.mu == 0.6
    assert scene.config.initial_pose == TWO.scene.initial_pose  # the scene given is unchanged
    # The same plan as on a plant built for the request's scene, bit for bit.
    shared = plan_request(request)
    built = plan_request(dataclasses.replace(request, scene=build_scene(request.config.scene)))
    assert shared.success and built.success, (shared.status, built.status)
    for name in TRAJECTORY_ARRAYS:
        np.testing.assert_array_equal(getattr(shared.trajectory, name), getattr(built.trajectory, name))


def test_a_scene_of_another_object_or_hand_is_not_shared(scene):
    for other in (dict(box_width=0.15), dict(gravity=5.0), dict(hand="fingerpro4")):
        with pytest.raises(ValueError, match="differ in more than"):
            scene.for_planning(dataclasses.replace(scene.config, **other))


def test_a_worker_solves_a_replans_pieces_on_the_plant_it_built():
    first = SceneConfig(mu=0.7)
    again = dataclasses.replace(first, mu=0.41, box_mass=0.06, initial_pose=(0.01, 0.0, 0.4))
    a, b = worker_scene(first), worker_scene(again)
    assert b.plant is a.plant and b.config == again and a.config == first
    assert worker_scene(dataclasses.replace(first, box_width=0.18)).plant is not a.plant


def test_a_replanned_plans_segments_are_ready_when_their_own_chain_is(scene):
    three = find_contact_plan(scene, GOAL, THREE.search)
    assert three.success and len(three.nodes) == 4, three.reason
    since = time.perf_counter()
    pieces, attempts, ready = solve_first_segment_first(three, THREE, workers=2, scene=scene, since=since)
    assert all(p.success for p in pieces)
    for s in range(3):  # its own last attempt's return, whatever its neighbours' chains took
        assert ready[s] == max(r.finished_s for r in attempts[s]) - since
    # Without joint retries a failing segment's chain is all it gets (executed up to it, then planned again).
    pieces, attempts = solve_segments(three, FAILING, workers=2, joint_retries=False)
    assert [[r.kind for r in tried] for tried in attempts.values()] == [["keyframes", "restart", "strict"]] * 3
    assert [(p.kind, p.first, p.last, p.success) for p in pieces] == [("strict", s, s + 1, False) for s in range(3)]
