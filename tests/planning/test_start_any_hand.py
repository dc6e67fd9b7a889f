"""Start states on every hand (trajectotree.start, trajectotree.planning.start): sized by the hand
(planar_hand5's 10 joints, Drake's gripper's 6), and refused before any planning when they do not
fit it: another number of joint angles or contacts, a joint outside its limits (q0 + 2 pi puts the
fingertip where it was), the object beyond the scene's bounds, `true` for an angle."""

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, SceneConfig
from trajectotree.io import load_start, save_start
from trajectotree.planning.start import StartProblem, StartRefused, start_config
from trajectotree.scene.hand import with_hand_object
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan
from trajectotree.start import StartState

HANDS = {"planar_hand5": (10, 2.0), "drake_planar_gripper": (6, 1.0)}  # joints, a goal the search plans


def hand_config(hand: str) -> Config:
    """The config the CLI's --hand gives: the hand's own object (Drake's gripper: its brick)."""
    return Config(scene=with_hand_object(SceneConfig(hand=hand)))


@pytest.fixture(scope="module", params=list(HANDS))
def hand_start(request):
    """(hand, scene, config, a start at node 3 of the search's plan: every finger on the object, at rest)."""
    hand = request.param
    config = hand_config(hand)
    scene = build_scene(config.scene)
    contact_plan = find_contact_plan(scene, HANDS[hand][1], config.search)
    assert contact_plan.success, contact_plan.reason
    node = contact_plan.nodes[3]
    return hand, scene, config, StartState(object_pose=tuple(node.object_pose), q=tuple(node.q))


def test_a_start_has_the_hands_joints_and_round_trips(hand_start, tmp_path):
    hand, scene, config, start = hand_start
    assert len(start.q) == HANDS[hand][0] == scene.num_hand_joints
    path = tmp_path / "start.json"
    save_start(start, path)
    assert load_start(path) == start
    planned = start_config(scene, start, config)
    assert len(planned.search.initial_arclengths) == scene.num_fingers
    assert planned.scene.initial_pose == start.object_pose
    # a run's arrays (sim.npz: t, x, q of the hand's joints) give the same start at a sample
    t = np.array([0.0, 0.1, 0.2])
    x, q = np.tile(start.object_pose, (3, 1)), np.tile(start.q, (3, 1))
    assert StartState.from_run(t, x, q, 0.1) == start


def test_a_start_of_another_size_is_refused_naming_both_counts(hand_start):
    hand, scene, config, start = hand_start
    eight = StartState(object_pose=start.object_pose, q=start.q[:4] + start.q[:4])  # the four-finger hand's
    with pytest.raises(StartRefused, match=rf"start.q has 8 entries; the hand has {HANDS[hand][0]} joint angles") as e:
        start_config(scene, eight, config)
    assert e.value.refusal.problem is StartProblem.WRONG_SIZE
    contacts = StartState(object_pose=start.object_pose, q=start.q, arclengths=(0.0,) * (scene.num_fingers + 1))
    with pytest.raises(StartRefused, match=rf"start.arclengths has {scene.num_fingers + 1} entries; the hand has "):
        start_config(scene, contacts, config)


@pytest.mark.parametrize("joint, turn", [(0, 2 * math.pi), (1, -2 * math.pi)])
def test_a_joint_a_turn_beyond_its_limit_is_refused_though_its_fingertip_is_where_it_was(hand_start, joint, turn):
    hand, scene, config, start = hand_start
    q = np.array(start.q)
    q[joint] += turn
    np.testing.assert_allclose(scene.fingertip_positions(q), scene.fingertip_positions(np.array(start.q)), atol=1e-12)
    finger = scene.hand_description.fingers[0]
    low, high = finger.q_lower[joint], finger.q_upper[joint]
    name = finger.joints[joint]
    with pytest.raises(StartRefused) as e:
        start_config(scene, StartState(object_pose=start.object_pose, q=tuple(q)), config)
    refusal = e.value.refusal
    assert (refusal.problem, refusal.finger, refusal.name, refusal.index) == (StartProblem.JOINT_LIMIT, 0, name, joint)
    assert str(e.value) == (
        f"start.q[{joint}] = {q[joint]:.6g} rad (finger 0, joint {name!r}) is outside its limits; "
        f"valid range: [{low:g}, {high:g}] rad"
    )
    assert refusal.to_json() == {
        "kind": "start",
        "problem": "joint_limit",
        "value": q[joint],
        "limit": high,
        "lower": low,
        "finger": 0,
        "name": name,
        "index": joint,
    }


def test_an_object_beyond_the_scenes_bounds_is_refused_without_overflow(hand_start):
    hand, scene, config, start = hand_start
    for k, value, text in ((0, 1e308, "[-1, 1] m"), (1, -1.5, "[-1, 1] m"), (2, 101.0, "[-100, 100] rad")):
        pose = list(start.object_pose)
        pose[k] = value
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no overflow on the way to the refusal
            with pytest.raises(StartRefused, match=rf"start.object_pose\[{k}\] = .* valid range: \{text}") as e:
                start_config(scene, StartState(object_pose=tuple(pose), q=start.q), config)
        assert e.value.refusal.problem is StartProblem.OUT_OF_BOUNDS and e.value.refusal.value == value


def test_true_false_and_nan_are_not_numbers():
    with pytest.raises(ConfigError, match=r"start.q\[1\] = True is not a finite number"):
        StartState(object_pose=(0.0, 0.0, 0.0), q=(0.0, True, 0.0))
    with pytest.raises(ConfigError, match=r"start.q = \(\) must have one or more numbers"):
        StartState(object_pose=(0.0, 0.0, 0.0), q=())
    with pytest.raises(ConfigError, match=r"start.json: q\[0\] = true must be a number"):
        StartState.from_json({"object_pose": [0, 0, 0], "q": [True, 0.5]})
    with pytest.raises(ConfigError, match=r"object_pose\[2\] = false must be a number"):
        StartState.from_json({"object_pose": [0, 0, False], "q": [0.5]})
    with pytest.raises(ConfigError, match=r"start.json: start.q\[0\] = nan is not a finite number"):
        StartState.from_json({"object_pose": [0, 0, 0], "q": [float("nan")]})
    with pytest.raises(ConfigError, match=r"q\[0\] = \"1.0\" must be a number"):
        StartState.from_json({"object_pose": [0, 0, 0], "q": ["1.0"]})


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_plan_start_refuses_each_reproducer_with_exit_2_and_writes_nothing(hand_start, tmp_path, capsys):
    hand, _, _, start = hand_start
    joints = HANDS[hand][0]
    good = start.to_json()
    cases = {
        "eight joints": (dict(good, q=good["q"][:4] * 2), f"start.q has 8 entries; the hand has {joints} joint angles"),
        "q0 + 2 pi": (
            dict(good, q=[good["q"][0] + 2 * math.pi, *good["q"][1:]]),
            "(finger 0, joint ",
        ),
        "x 1e308": (
            dict(good, object_pose=[1e308, 0, 0]),
            "start.object_pose[0] = 1e+308 m (x) is outside the scene's",
        ),
        "true": (dict(good, q=[True, *good["q"][1:]]), "q[0] = true must be a number"),
    }
    out = tmp_path / "out"
    for name, (data, message) in cases.items():
        path = tmp_path / "start.json"
        path.write_text(json.dumps(data))
        assert main(["plan", "--hand", hand, "--goal", "1.0", "--start", str(path), "--out", str(out)]) == 2, name
        line = one_line_error(capsys)
        assert message in line, (name, line)
        assert not out.exists(), name


def test_the_tester_s_overflow_reproducer_warns_nothing(tmp_path):
    """`object_pose: [1e308, 0, 0]` on the default hand, in a process of its own: exit 2, one line, no warning."""
    path = tmp_path / "start.json"
    path.write_text(json.dumps({"object_pose": [1e308, 0, 0], "q": [-0.7, 1.3] * 4}))
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "trajectotree.cli", "plan", "--goal", "1", "--start", str(path), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "trajectotree plan: error: start.object_pose[0] = 1e+308 m (x) is outside the scene's bounds; "
        "valid range: [-1, 1] m"
    ]
    assert not out.exists()


@pytest.mark.slow
def test_planar_hand5_replans_at_friction_0_4_and_plans_from_a_state_of_its_run(tmp_path, capsys):
    """The tester's reproducer (simulate --replan exited 2 on "must have 8 numbers"), a world with less friction
    than planned: the closed loop replans at a node with the estimate and the run (one continuous log) holds the
    object to the goal; then `state` at a node of the run and `plan --start` from it."""
    run = tmp_path / "h5"
    assert main(["plan", "--hand", "planar_hand5", "--goal", "2", "--out", str(run)]) == 0
    capsys.readouterr()
    # Deadlines no busy machine meets too late (as tests/execution/test_replan.py's) for a replan from the measured
    # state: at the default 0.5 s search and 1 s first segment every such replan ended first_segment_late under
    # load. A friction replan plans from the next node, within the 1.2 s to it, which no setting lengthens.
    deadlines = "{controller: {replan: {search_deadline_s: 30, first_segment_deadline_s: 300}}}"
    assert main(["simulate", str(run), "--replan", "--sim-mu", "0.4", "--config-text", deadlines, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert json.loads((run / "sim.json").read_text()) == summary
    replans = summary["replans"]
    assert not summary["dropped"], replans
    assert abs(summary["final_error"][2]) < math.radians(3)
    # the friction estimate falls below the plan's 0.7: the closed loop plans again from a 10-joint node state
    assert [r["outcome"] for r in replans].count("planned") >= 1, replans
    event = replans[0]
    assert event["reason"] == "friction" and 0.3 <= event["mu"] <= 0.45, event
    assert event["mass"] == pytest.approx(hand_config("planar_hand5").scene.box_mass, rel=0.05)
    # decided at a node of the plan (1.2 s segments), planned from the next one while the hand went on
    node = round(event["time_s"] / 1.2)
    assert event["time_s"] == pytest.approx(node * 1.2) and event["start_s"] == pytest.approx(node * 1.2 + 1.2)
    if event["planned"]:  # swapped in at that node, never before its compute time had passed
        assert event["takes_effect_s"] == event["start_s"] >= event["time_s"] + event["latency_s"]
    else:  # the old plan went on without a hold
        assert event["takes_effect_s"] == event["time_s"]
    assert all(e["latency_s"] <= e["compute_s"] + 1e-9 for e in replans if e["compute_s"] is not None)
    with np.load(run / "sim.npz") as npz:  # one log over the whole run
        t = npz["t"]
    with np.load(run / "plan.npz") as npz:
        assert np.all(np.diff(t) > 0) and t[-1] >= npz["t"][-1]
    start = tmp_path / "start.json"
    assert main(["state", str(run), "--time", "2.4", "--out", str(start)]) == 0  # node 2 of 1.2 s segments
    assert len(load_start(start).q) == 10
    again = tmp_path / "from_start"
    assert main(["plan", "--hand", "planar_hand5", "--start", str(start), "--goal", "2.5", "--out", str(again)]) == 0
    assert (again / "plan.json").is_file()


def test_a_start_moving_at_1e308_m_s_is_refused_as_moving_without_overflow(hand_start):
    hand, scene, config, start = hand_start
    fast = StartState(object_pose=start.object_pose, q=start.q, object_velocity=(1.7e308, 1.7e308, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(StartRefused, match=r"the object moves at inf m/s; a plan starts at rest \(at most 0.1"):
            start_config(scene, fast, config)
