"""Plans from a measured start state (trajectotree.start, trajectotree.planning.start): a node of a
plan moved 5 mm and 0.1 rad, re-grasped at the same contacts, planned from and executed; and the
starts that are refused before any planning, each naming its finger, value and limit."""

import dataclasses
import json

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, SceneConfig
from trajectotree.geometry import box_to_world, rotation_2d
from trajectotree.io import load_start, save_start
from trajectotree.planning.planners import plan
from trajectotree.planning.start import StartProblem, StartRefused, start_config
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.tree import find_contact_plan
from trajectotree.start import StartState

CONFIG = Config()


@pytest.fixture(scope="module")
def scene():
    return build_scene(CONFIG.scene)


@pytest.fixture(scope="module")
def moved_node(scene):
    """Node 7 of the search's plan for 0.9 rad, the object 5 mm right and 0.1 rad further turned,
    the fingers re-solved (closed-form IK) onto the same contacts (the paper's order of the search's
    children: its node 7 needs more friction than 0.035, which the refusals below use). Node 4, used
    before the fingers were kept apart, is now another grasp whose finger 2 cannot reach its contact so moved."""
    contact_plan = find_contact_plan(scene, 0.9, dataclasses.replace(CONFIG.search, push_capacity=0.0))
    node = contact_plan.nodes[7]
    pose = node.object_pose + np.array([0.005, 0.0, 0.1])
    hand = HandModel.from_scene(scene)
    tips = [box_to_world(pose, node.p_BC[i]) + scene.tip_radius * rotation_2d(pose[2]) @ node.n_B[i] for i in range(4)]
    q = np.concatenate([hand.ik(i, tips[i]) for i in range(NUM_FINGERS)])
    return node, StartState(object_pose=tuple(pose), q=tuple(q))


def test_contacts_are_derived_from_the_fingertips(scene, moved_node):
    node, start = moved_node
    config = start_config(scene, start, CONFIG)
    np.testing.assert_allclose(config.search.initial_arclengths, node.arclengths, atol=1e-9)
    assert config.scene.initial_pose == start.object_pose


@pytest.mark.slow
def test_a_plan_from_a_moved_node_begins_at_it_reaches_the_goal_and_executes(scene, moved_node):
    from trajectotree.execution.run import run_simulation

    node, start = moved_node
    result = plan(goal=1.2, start=start, scene=scene, config=CONFIG)
    assert result.success, result.status
    x, q = result.trajectory.x, result.trajectory.q
    np.testing.assert_allclose(x[0], start.object_pose, atol=1e-9)  # the first knot is the measured state
    np.testing.assert_allclose(q[0], start.q, atol=1e-9)
    np.testing.assert_allclose(result.contact_plan.nodes[0].arclengths, node.arclengths, atol=1e-9)
    np.testing.assert_allclose(x[-1], [start.object_pose[0], start.object_pose[1], 1.2], atol=1e-9)
    run = run_simulation(plan=result)
    assert not run.dropped
    assert abs(run.x[-1, 2] - 1.2) < np.radians(3)


def test_refusals_name_the_finger_the_value_and_the_limit(scene, moved_node):
    _, start = moved_node
    with pytest.raises(
        StartRefused, match=r"the object moves at 0.15 m/s; a plan starts at rest \(at most 0.1 m/s\)"
    ) as e:
        start_config(scene, dataclasses.replace(start, object_velocity=(0.15, 0.0, 0.0)), CONFIG)
    assert e.value.refusal.problem is StartProblem.MOVING
    lifted = np.array(start.q)
    lifted[5] += 0.2  # finger 2's second joint: its tip leaves the surface
    with pytest.raises(StartRefused, match=r"fingertip 2 is .* mm from the object's surface") as e:
        start_config(scene, dataclasses.replace(start, q=tuple(lifted)), CONFIG)
    assert e.value.refusal.finger == 2 and e.value.refusal.value > 2e-3
    slippery = Config(scene=SceneConfig(mu=0.05))
    with pytest.raises(StartRefused, match=r"not in frictional form closure at mu_plan 0.035; it needs mu") as e:
        start_config(build_scene(slippery.scene), start, slippery)
    assert e.value.refusal.value > 0.035
    wrong = dataclasses.replace(start, arclengths=(0.0, 0.1, 0.2, 0.3))
    with pytest.raises(StartRefused, match=r"finger 0's given contact is .* mm from its fingertip"):
        start_config(scene, wrong, CONFIG)


def test_start_files_round_trip_and_bad_ones_exit_2_writing_nothing(moved_node, tmp_path, capsys):
    _, start = moved_node
    path = tmp_path / "start.json"
    save_start(start, path)
    assert load_start(path) == start
    cases = {
        "binary.json": (b"\x89PNG\x00\xff", "is not a JSON start state"),
        "list.json": (b"[1, 2]", "a start state is a JSON object"),
        "short.json": (json.dumps({"object_pose": [0, 0], "q": [0] * 8}).encode(), "start.object_pose = (0.0, 0.0)"),
        "nan.json": (json.dumps({"object_pose": [0, 0, "x"], "q": [0] * 8}).encode(), "must be a number"),
        "extra.json": (json.dumps({"object_pose": [0, 0, 0], "q": [0] * 8, "v": 1}).encode(), "unknown key(s) ['v']"),
    }
    out = tmp_path / "out"
    for name, (data, message) in cases.items():
        (tmp_path / name).write_bytes(data)
        assert main(["plan", "--goal", "0.5", "--start", str(tmp_path / name), "--out", str(out)]) == 2
        assert message in capsys.readouterr().err, name
    lifted = dict(start.to_json(), q=[v + (0.3 if i == 1 else 0.0) for i, v in enumerate(start.q)])
    (tmp_path / "lifted.json").write_text(json.dumps(lifted))
    assert main(["plan", "--goal", "0.5", "--start", str(tmp_path / "lifted.json"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "fingertip 0 is" in err and "every finger must touch it (within " in err  # the value and the limit
    # a grasp that holds at mu 0.7 but not at 0.05: the friction it needs, beside mu_plan's 0.035
    assert main(["plan", "--goal", "0.5", "--start", str(path), "--mu", "0.05", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not in frictional form closure at mu_plan 0.035; it needs mu " in err, err
    assert not out.exists()
