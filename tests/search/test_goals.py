"""Goal poses and multi-turn goals: the segments follow from the distance, the search follows a
translating and many-turn path to its end, the workspace says where the hand can carry the object,
and a fresh process searches without importing scipy."""

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest
from test_search import check_plan

from trajectotree.config import MAX_NODES, ConfigError, GoalPose, SearchConfig, segments_for, with_segments
from trajectotree.results import check_goal
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import initial_grasp_candidates
from trajectotree.search.tree import find_contact_plan, object_path
from trajectotree.search.workspace import Graspability, check_goal_position, workspace


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def grasp(scene):
    return Graspability(scene, SearchConfig())


def test_segments_follow_from_the_distance():
    search, start = SearchConfig(), (0.0, 0.0, 0.0)
    # the paper's 9 for every goal within pi, either way
    for theta in (0.05, -1.0, math.pi, -math.pi):
        assert segments_for(search, start, GoalPose(theta)) == 9
    # one more per pi/12 beyond: 2 pi 21, 4 pi 45, 8 pi 93 (the paper's rate, pi/9, has no 2 pi plan)
    assert [segments_for(search, start, GoalPose(k * math.pi)) for k in (2, -4, 8)] == [21, 45, 93]
    assert segments_for(search, start, GoalPose(math.pi + 1e-3)) == 10
    # the distance is from the start's orientation and position
    assert segments_for(search, (0.0, 0.0, 2 * math.pi), GoalPose(3 * math.pi)) == 9
    assert segments_for(search, (0.01, 0.0, 0.0), GoalPose(0.0, (0.11, 0.0))) == 10  # 0.1 m at 0.01 m each
    # --segments (search.num_nodes) wins; a goal needing more than MAX_NODES is refused
    assert segments_for(dataclasses.replace(search, num_nodes=4), start, GoalPose(8 * math.pi)) == 3
    assert with_segments(search, start, GoalPose(2 * math.pi)).num_nodes == 22
    with pytest.raises(ConfigError, match=f"at most {MAX_NODES} nodes"):
        segments_for(dataclasses.replace(search, max_segment_rotation=0.01), start, GoalPose(20 * math.pi))


def test_the_goal_check():
    assert check_goal(8 * math.pi) == GoalPose(8 * math.pi)
    assert check_goal((0.01, -0.02, -3 * math.pi)) == GoalPose(-3 * math.pi, (0.01, -0.02))
    assert check_goal(np.float64(2.0)) == GoalPose(2.0)
    for bad, named in (
        (20 * math.pi + 1e-6, "goal = "),
        ((0.0, 0.0, 70.0), "goal[2] = 70.0"),
        ((3.0, 0, 0), "goal[0]"),
    ):
        with pytest.raises(ConfigError, match=re_escape(named)):
            check_goal(bad)
    with pytest.raises(ConfigError, match="goal.theta: is not given"):
        check_goal(GoalPose(position=(0.0, 0.0)))
    with pytest.raises(ConfigError, match=re_escape("goal.position[1] = 2.0 is out of range")):
        GoalPose(1.0, (0.0, 2.0))


def re_escape(text: str) -> str:
    import re

    return re.escape(text)


def test_the_path_translates_and_turns():
    path = object_path((0.01, 0.0, 0.5), GoalPose(0.5 + 4 * math.pi, (0.03, -0.02)), 5)
    np.testing.assert_allclose(path[0], (0.01, 0.0, 0.5))
    np.testing.assert_allclose(path[-1], (0.03, -0.02, 0.5 + 4 * math.pi))
    np.testing.assert_allclose(np.diff(path, axis=0), [[0.005, -0.005, math.pi]] * 4, atol=1e-12)
    # a rotation goal keeps the start's position, as before
    np.testing.assert_array_equal(object_path((0.0, 0.0, 0.0), 1.0, 3)[:, :2], 0.0)


@pytest.mark.slow  # about 8 s of search since the fingers are kept apart
def test_a_four_turn_plan_ends_at_the_goal(scene):
    # +4 pi: 46 nodes, searched window by window; every node checked independently. -4 pi has no
    # plan within the search's budgets since the fingers are kept apart (docs/results.md). Its expansions bound it,
    # not the 30 s of wall clock, which a loaded machine ran out of
    config = SearchConfig(time_budget_s=600.0)
    plan = find_contact_plan(scene, 4 * math.pi, config)
    check_plan(scene, plan, config)
    assert len(plan.nodes) == 46 and plan.nodes[-1].object_pose[2] == pytest.approx(4 * math.pi)
    switches = sum(n.switching_finger is not None for n in plan.nodes)
    assert switches >= 30  # each finger regrasps around the object about four times per turn


def test_a_translated_plan_ends_at_the_goal_pose(scene):
    config = SearchConfig()
    goal = GoalPose(0.8, (0.02, 0.01))
    plan = find_contact_plan(scene, goal, config)
    check_plan(scene, plan, config)  # the IK puts every fingertip on its contact at the moved poses
    assert plan.goal_position == (0.02, 0.01)
    np.testing.assert_allclose(plan.nodes[-1].object_pose, (0.02, 0.01, 0.8), atol=1e-12)
    assert not np.allclose(plan.nodes[4].object_pose[:2], 0.0)  # the nodes between move too


def test_graspability_is_the_initial_grasp_tables(scene, grasp):
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-0.1, 0.1, 24), rng.uniform(-0.08, 0.08, 24), rng.uniform(-7, 7, 24)])
    tables = [
        bool(
            initial_grasp_candidates(
                dataclasses.replace(scene, config=dataclasses.replace(scene.config, initial_pose=tuple(p))),
                SearchConfig(),
                grasp.reach,
            ).candidates
        )
        for p in poses
    ]
    assert grasp.at(poses).tolist() == tables and 0 < sum(tables) < len(tables)


def test_the_workspace_and_a_goal_outside_it(scene, grasp):
    space = workspace(scene, SearchConfig(), grasp)
    every, start = space.to_json()["every_orientation"], space.to_json()["start_orientation"]
    assert 0.02 < every["radius_m"] < start["radius_m"] and every["points"] < start["points"]
    assert grasp.at(np.column_stack([space.every_orientation, np.full(len(space.every_orientation), 2.0)])).all()
    check_goal_position(scene, SearchConfig(), GoalPose(6.0, (0.02, 0.0)), grasp=grasp)  # inside: nothing raised
    check_goal_position(scene, SearchConfig(), GoalPose(6.0), grasp=grasp)  # no position: nothing to check
    with pytest.raises(ConfigError) as refused:
        check_goal_position(scene, SearchConfig(), GoalPose(0.0, (0.2, 0.0)), "--goal-pose X Y", grasp=grasp)
    text = str(refused.value)
    assert text.startswith("--goal-pose X Y = (0.2, 0) m is outside the hand's workspace: ")
    assert "no grasp of the object at node " in text and "valid: at most 0.1" in text
    limit = float(text.split("valid: at most ")[1].split(" m")[0])
    check_goal_position(scene, SearchConfig(), GoalPose(0.0, (limit, 0.0)), grasp=grasp)  # the stated limit holds


def test_a_fresh_process_searches_without_scipy():
    # pydrake's sparse-matrix caster imports scipy.sparse (0.2-0.9 s) when a row-major matrix meets
    # an overload taking one: the search's LPs pass column-major matrices, so a fresh process never does
    code = (
        "import sys\n"
        "from trajectotree.config import SearchConfig\n"
        "from trajectotree.scene.plant import build_scene\n"
        "from trajectotree.search.tree import find_contact_plan\n"
        "assert find_contact_plan(build_scene(), -0.77, SearchConfig()).success\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"
