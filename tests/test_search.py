"""The contact-sequence planner: every node of a found plan is checked independently
(form closure by a fresh LP, reachability by the plant's kinematics, collisions by
SceneGraph), on positive and negative goals and a non-default box and friction."""

import json
import subprocess
import sys

import numpy as np
import pytest

from trajectotree.config import ConfigError, SceneConfig, SearchConfig
from trajectotree.geometry import BoxBoundary, box_to_world, rotation_2d
from trajectotree.grasp import FormClosure
from trajectotree.scene import NUM_FINGERS, build_scene
from trajectotree.search import default_initial_arclengths, find_contact_plan

from test_reach import signed_distances


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def small_slippery_scene():
    return build_scene(SceneConfig(box_width=0.16, box_height=0.08, mu=0.5))


def check_plan(scene, plan, config: SearchConfig):
    c = scene.config
    boundary = BoxBoundary(c.box_width, c.box_height)
    closure = FormClosure(boundary, c.mu, config.min_closure_margin)
    assert plan.success, plan.reason
    assert len(plan.nodes) == config.num_nodes
    # object path: linear interpolation from the initial pose to the goal rotation
    np.testing.assert_allclose(plan.object_path[0], c.initial_pose)
    np.testing.assert_allclose(plan.object_path[-1], np.add(c.initial_pose, (0, 0, plan.goal)))
    np.testing.assert_allclose(np.diff(plan.object_path, axis=0), plan.goal / (config.num_nodes - 1) * np.array([[0, 0, 1]] * (config.num_nodes - 1)), atol=1e-12)
    # node 0 is the initial grasp
    initial = config.initial_arclengths or default_initial_arclengths(scene)
    np.testing.assert_allclose(plan.nodes[0].arclengths, np.mod(initial, boundary.perimeter), atol=1e-9)
    assert plan.nodes[0].switching_finger is None
    for n, node in enumerate(plan.nodes):
        result = closure.check(node.arclengths)
        assert result.in_closure and result.margin > config.min_closure_margin
        assert node.closure_margin == pytest.approx(result.margin, abs=1e-6)
        for i in range(NUM_FINGERS):
            p, normal = boundary.point(node.arclengths[i])
            np.testing.assert_allclose(node.p_BC[i], p, atol=1e-12)
            np.testing.assert_allclose(node.n_B[i], normal, atol=1e-12)
            assert boundary.signed_distance(node.p_BC[i]) == pytest.approx(0.0, abs=1e-12)
            assert boundary.corner_distance(node.arclengths[i]) >= c.corner_margin - 1e-12
        # the IK joint angles put every fingertip sphere on its contact, within joint limits
        p_WF = scene.fingertip_positions(node.q)
        for i, f in enumerate(scene.fingers):
            n_W = rotation_2d(node.object_pose[2]) @ node.n_B[i]
            target = box_to_world(node.object_pose, node.p_BC[i]) + scene.tip_radius * n_W
            np.testing.assert_allclose(p_WF[i], target, atol=1e-5)
            q = node.q[2 * i:2 * i + 2]
            assert np.all(q >= f.q_lower - 1e-7) and np.all(q <= f.q_upper + 1e-7)
        assert np.all(signed_distances(scene, node.object_pose, node.q) > -1e-6)  # no link enters the box
        if n == 0:
            continue
        before = plan.nodes[n - 1]
        changed = [i for i in range(NUM_FINGERS) if abs(node.arclengths[i] - before.arclengths[i]) > 1e-9]
        assert len(changed) <= 1  # at least three contacts shared
        assert changed == ([] if node.switching_finger is None else [node.switching_finger])
        if node.switching_finger is not None:  # the moving finger was free: the other three held the box
            others = [s for i, s in enumerate(before.arclengths) if i != node.switching_finger]
            assert closure.check(others).in_closure


@pytest.mark.parametrize("goal", [np.pi, -np.pi, 1.1, -2.3])
def test_plans_satisfy_every_node_condition(scene, goal):
    config = SearchConfig()
    plan = find_contact_plan(scene, goal, config)
    check_plan(scene, plan, config)
    s = plan.stats
    assert s.expanded >= config.num_nodes and s.lp_calls > 0 and s.ik_calls >= 4 * config.num_nodes


@pytest.mark.parametrize("goal", [1.5, -1.0])
def test_non_default_box_and_friction(small_slippery_scene, goal):
    config = SearchConfig()
    plan = find_contact_plan(small_slippery_scene, goal, config)
    check_plan(small_slippery_scene, plan, config)


def test_default_grasp_is_in_closure_and_reachable(scene):
    boundary = BoxBoundary(0.20, 0.10)
    grasp = default_initial_arclengths(scene)
    np.testing.assert_allclose(grasp, [0.54, 0.12, 0.36, 0.48], atol=1e-12)
    closure = FormClosure(boundary, 0.7, 1e-3)
    assert closure.check(grasp).in_closure
    # finger 1 is the only contact on top; any of the others may let go
    assert [closure.is_free(grasp, i) for i in range(NUM_FINGERS)] == [True, False, True, True]
    plan = find_contact_plan(scene, 0.0, SearchConfig(num_nodes=2))
    check_plan(scene, plan, SearchConfig(num_nodes=2))


def test_custom_initial_grasp_and_segments(scene):
    config = SearchConfig(num_nodes=5, initial_arclengths=(0.52, 0.14, 0.32, 0.5))
    check_plan(scene, find_contact_plan(scene, 0.8, config), config)


def test_failures_are_results_with_a_reason(scene):
    # all four contacts on the bottom face: not in form closure
    plan = find_contact_plan(scene, 0.5, SearchConfig(initial_arclengths=(0.43, 0.47, 0.51, 0.55)))
    assert not plan.success and "initial grasp" in plan.reason and plan.nodes == ()
    # a half turn in 3 nodes needs more contact switches than 2 steps allow
    plan = find_contact_plan(scene, np.pi, SearchConfig(num_nodes=3))
    assert not plan.success and "contact switches" in plan.reason
    # a tiny node budget
    plan = find_contact_plan(scene, np.pi, SearchConfig(max_expansions=3))
    assert not plan.success and "budget" in plan.reason and plan.stats.expanded == 3
    with pytest.raises(ConfigError):
        find_contact_plan(scene, float("nan"), SearchConfig())


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "trajectotree.cli", "search", *args], capture_output=True, text=True,
                          timeout=300)


def test_cli_json_and_figure(tmp_path):
    figure = tmp_path / "plan.png"
    out = run_cli("--goal", "-1.2", "--json", "--figure", str(figure), "--box-size", "0.16", "0.08", "--mu", "0.5")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["success"] and len(data["contact_sequence"]) == 10
    node = data["contact_sequence"][3]
    assert set(node) >= {"object_pose", "q", "switching_finger", "contacts"}
    assert len(node["q"]) == 8 and len(node["contacts"]) == 4 and set(node["contacts"][0]) >= {"arclength", "p_B", "n_B"}
    assert figure.stat().st_size > 10_000
    # a failed search still exits 0, with the reason
    out = run_cli("--goal", "3.0", "--segments", "2", "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["success"] is False
    # invalid input exits 2 and names the valid range
    out = run_cli("--goal", "4")
    assert out.returncode == 2 and "[-pi, pi]" in out.stderr
