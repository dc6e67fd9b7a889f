"""A hand in space's object options, its start state and its bad input on the command line (issue 36): --box-size
X Y Z, --mass and --mu reach the scene; every planar-only option of `scene`, `search` and `plan` exits 2 naming it;
a box the hand has no initial grasp of and a start that does not fit the hand exit 2 naming the value and the limit,
before anything is written; a saved start state plans from its grasp."""

import dataclasses
import json
import math

import numpy as np
import pytest

from trajectotree.cli import build_parser, main
from trajectotree.cli.space_options import FINGERPRO4_CUBES_M, PLANAR_ONLY
from trajectotree.config import Config, mu_plan
from trajectotree.geometry import quaternion_angle
from trajectotree.planning.start import SPACE_TOUCH_DISTANCE, StartRefused, space_start_root
from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.search.space_tree import find_space_contact_plan
from trajectotree.search.spatial_reach import SpatialReach, box_transform
from trajectotree.start import SpaceStartState, StartProblem

SPACE = ["--hand", "fingerpro4"]
HALF_TURN_ABOUT_Z = ["--goal-rpy", "0", "0", "0.5"]
# What each command does with a hand in space (argparse dests); PLANAR_ONLY holds the rest. An option added to a
# command fails test_every_option_is_used_or_refused until it is sorted into one of them.
SPACE_USED = {
    "scene": {"config", "config_text", "box_size", "mass", "mu", "hand", "json"},
    "search": {"goal", "goal_pose", "goal_quat", "goal_rpy", "config", "config_text", "box_size", "mass", "mu", "hand"}
    | {"figure", "json"},
    "plan": {"goal", "goal_pose", "goal_quat", "goal_rpy", "method", "config", "config_text", "box_size", "mass"}
    | {"mu", "hand", "start", "segment_workers", "out", "json", "html", "formulation"},
    "demo": {"goal", "goal_quat", "goal_rpy", "config", "config_text", "box_size", "mass", "mu", "hand", "out"}
    | {"formulation"}
    | {"meshcat", "json"},
}
# A value for each planar-only option (the goal options are space_goal's: "is a planar goal")
PLANAR_VALUES = {
    "polygon": ["-0.05,-0.04 0.05,-0.04 0,0.06"],
    "circle": ["0.05"],
    "ellipse": ["0.05", "0.03"],
    "segments": ["4"],
    "formulation": ["joint"],
    "figure": ["model.png"],
    "rotations": [],
}


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def _refused(capsys, argv: list[str], *needles: str) -> str:
    """Runs `argv`, which must exit 2 with one line on stderr holding each of `needles`; returns the line."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.mark.parametrize("command", sorted(SPACE_USED))
def test_every_option_is_used_or_refused(command):
    parser = build_parser(command)._subparsers._group_actions[0].choices[command]
    dests = {a.dest for a in parser._actions if a.dest != "help"}
    assert dests == SPACE_USED[command] | set(PLANAR_ONLY[command])


@pytest.mark.parametrize("command, dest", [(c, d) for c in sorted(PLANAR_ONLY) for d in PLANAR_ONLY[c]])
def test_a_planar_option_on_a_hand_in_space_exits_2_naming_it(tmp_path, capsys, command, dest):
    option, out = "--" + dest.replace("_", "-"), tmp_path / "out"
    argv = [command, *SPACE, option, *PLANAR_VALUES[dest]]
    argv += {
        "scene": [],
        "search": HALF_TURN_ABOUT_Z,
        "plan": [*HALF_TURN_ABOUT_Z, "--out", str(out)],
        "demo": [*HALF_TURN_ABOUT_Z, "--out", str(out)],
        "sweep": ["--out", str(out)],
    }[command]
    _refused(capsys, argv, f"{option} = ", "is a planar hand's option; the hand 'fingerpro4' is in space")
    assert not out.exists() and not (tmp_path / "model.png").exists()


def test_formulation_keyframes_is_what_space_plans_with_and_is_no_ignored_option(tmp_path, capsys):
    out = tmp_path / "out"  # refused by the box check after the options: no planning
    argv = ["plan", *SPACE, *HALF_TURN_ABOUT_Z, "--formulation", "keyframes", "--box-size", "0.3", "0.3", "0.3"]
    _refused(capsys, [*argv, "--out", str(out)], "--box-size = 0.3 0.3 0.3 m")
    assert not out.exists()


def test_box_size_mass_and_mu_reach_the_scene_in_space(capsys):
    argv = ["scene", *SPACE, "--box-size", "0.08", "0.07", "0.06", "--mass", "0.2", "--mu", "0.8", "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    o = report["object"]
    assert o["size_m"] == [0.08, 0.07, 0.06] and o["mass_kg"] == 0.2 and o["mu"] == 0.8
    assert report["initial_grasps"]["count"] > 0


def test_the_scene_command_reports_a_box_without_an_initial_grasp(capsys):
    assert main(["scene", *SPACE, "--box-size", "0.02", "0.02", "0.02"]) == 0  # a report, not a plan: no refusal
    assert "initial grasps at the grasp point" in capsys.readouterr().out.splitlines()[-1]
    assert main(["scene", *SPACE, "--box-size", "0.02", "0.02", "0.02", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["initial_grasps"]["count"] == 0


def test_config_text_reaches_a_hand_in_space(capsys):
    assert main(["scene", *SPACE, "--config-text", "{scene: {mu: 0.7}}", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["object"]["mu"] == 0.7


@pytest.mark.parametrize(
    "argv, needles",
    [
        ([*SPACE, "--box-size", "0.3", "0.3"], ("--box-size = [0.3, 0.3] has 2 values", "X Y Z (3, m) for a hand")),
        ([*SPACE, "--box-size", "0.3"], ("--box-size = [0.3] has 1 value;",)),
        (["--box-size", "0.1", "0.1", "0.1"], ("--box-size = [0.1, 0.1, 0.1] has 3 values", "'planar_hand' is planar")),
        ([*SPACE, "--box-size", "0.1", "0", "0.1"], ("--box-size[1] = 0.0 is out of range; valid range: (0, 0.3]",)),
        ([*SPACE, "--box-size", "0.1", "nan", "0.1"], ("--box-size[1] = nan is not a finite number",)),
    ],
)
def test_a_box_size_of_the_wrong_count_or_range_exits_2(tmp_path, capsys, argv, needles):
    out = tmp_path / "out"
    goal = ["--goal", "0.5"] if "--hand" not in argv else HALF_TURN_ABOUT_Z
    _refused(capsys, ["plan", *argv, *goal, "--out", str(out)], *needles)
    assert not out.exists()


@pytest.mark.parametrize("command", ["search", "plan"])
@pytest.mark.parametrize("size", ["0.02", "0.29"])
def test_a_box_the_fingers_cannot_grasp_is_refused_before_planning(tmp_path, capsys, command, size):
    out = tmp_path / "out"
    argv = [command, *SPACE, *HALF_TURN_ABOUT_Z, "--box-size", size, size, size]
    low, high = FINGERPRO4_CUBES_M
    _refused(
        capsys,
        argv + (["--out", str(out)] if command == "plan" else ["--figure", str(tmp_path / "f.png")]),
        f"--box-size = {size} {size} {size} m: the hand 'fingerpro4' has no initial grasp of this box",
        f"cubes of {low:g} to {high:g} m per side",
    )
    assert not out.exists() and not (tmp_path / "f.png").exists()


def test_a_box_too_heavy_to_hold_names_the_mass(tmp_path, capsys):
    out = tmp_path / "out"
    _refused(
        capsys,
        ["plan", *SPACE, *HALF_TURN_ABOUT_Z, "--mass", "5", "--out", str(out)],
        "--mass = 5.0 kg: no initial grasp of the 0.065 0.065 0.065 m box holds it within the motors (0.396 N m)",
    )
    assert not out.exists()


def test_demo_refuses_a_box_the_hand_cannot_grasp(tmp_path, capsys):
    out = tmp_path / "demo"
    _refused(capsys, ["demo", *SPACE, "--box-size", "0.29", "0.29", "0.29", "--out", str(out)], "--box-size = ")
    assert not out.exists()


# -- a saved start state --------------------------------------------------------------------------------------------
def _turned_grasp(scene) -> SpaceStartState:
    """The grasp the search holds the cube in at the end of a 0.5 rad turn about z (its last node: every fingertip
    on its contact by IK), as a measured start."""
    config = Config()
    goal = np.array([math.cos(0.25), 0.0, 0.0, math.sin(0.25)])
    plan = find_space_contact_plan(scene, goal, config.search, mu_plan(config.scene, config.search))
    assert plan.success, plan.reason
    last = plan.nodes[-1]
    return SpaceStartState(object_pose=tuple(last.object_pose), q=tuple(np.ravel(last.q)))


@pytest.fixture(scope="module")
def turned(scene) -> SpaceStartState:
    return _turned_grasp(scene)


def _write(tmp_path, start: dict) -> str:
    path = tmp_path / "start.json"
    path.write_text(json.dumps(start))
    return str(path)


def _variant(start: SpaceStartState, **changes) -> dict:
    return start.to_json() | changes


def _q_with(start: SpaceStartState, k: int, value: float) -> list[float]:
    q = list(start.q)
    q[k] = value
    return q


@pytest.mark.parametrize(
    "change, needles",
    [
        (lambda s: _variant(s, q=list(s.q)[:9]), ("start.q has 9 entries; the hand has 12 joint angles",)),
        (lambda s: _variant(s, q=_q_with(s, 2, -4.0)), ("start.q[2] = -4 rad (finger 0, joint 'finger0_joint3')",)),
        (lambda s: _variant(s, q=_q_with(s, 4, s.q[4] + 0.05)), ("start: fingertip 1 is", "(within 1 mm)")),
        (lambda s: _variant(s, object_pose=[0.0] * 7), ("start.object_pose[0:4] = [0.0, 0.0, 0.0, 0.0] has norm 0",)),
        (lambda s: _variant(s, object_velocity=[0, 0, 0, 0.5, 0, 0]), ("moves at 0.5 m/s", "(at most 0.1 m/s)")),
        (lambda s: _variant(s, object_velocity=[0, 0, 3, 0, 0, 0]), ("turns at 3 rad/s", "(at most 1)")),
        (lambda s: _variant(s, contacts=[[0.0, 0.0, 0.0]] * 4), ("finger 0's given contact is", "at most 1 mm")),
        (lambda s: _variant(s, contacts=[[0.0, 0.0, 0.0]] * 3), ("start.contacts has 3 entries; the hand has 4",)),
    ],
)
def test_a_start_that_does_not_fit_the_hand_exits_2_naming_the_value_and_the_limit(
    tmp_path, capsys, turned, change, needles
):
    out = tmp_path / "out"
    start = _write(tmp_path, change(turned))
    _refused(capsys, ["plan", *SPACE, "--goal-rpy", "0", "0", "1", "--start", start, "--out", str(out)], *needles)
    assert not out.exists()


def test_a_start_with_nan_is_refused_naming_the_entry(tmp_path, capsys, turned):
    path = tmp_path / "start.json"
    path.write_text(json.dumps(turned.to_json()).replace(str(turned.q[3]), "NaN", 1))
    out = tmp_path / "out"
    _refused(capsys, ["plan", *SPACE, *HALF_TURN_ABOUT_Z, "--start", str(path), "--out", str(out)], "start.q[3] = nan")
    assert not out.exists()


def test_a_fingertip_just_over_the_limit_is_refused_with_its_distance(scene, turned):
    """A fingertip moved 1.5 mm out along its face's normal: FINGER_OFF naming the finger, 1.5 mm and 1 mm."""
    root = space_start_root(scene, turned, Config())
    n_B = np.zeros(3)
    n_B[root.faces[2] // 2] = 1.0 if root.faces[2] % 2 == 0 else -1.0
    R = box_transform(turned.object_pose).rotation().matrix()
    target = scene.fingers[2].fingertip(root.q[2]) + R @ n_B * 1.5e-3
    p_BF = R.T @ (target - np.asarray(turned.object_pose[4:]))
    reach = SpatialReach(scene).solve(turned.object_pose, 2, p_BF, root.q[2])
    q = root.q.copy()
    q[2] = reach.q
    moved = SpaceStartState(object_pose=turned.object_pose, q=tuple(q.ravel()))
    with pytest.raises(StartRefused) as refused:
        space_start_root(scene, moved, Config())
    r = refused.value.refusal
    assert r.problem is StartProblem.FINGER_OFF and r.finger == 2 and r.limit == SPACE_TOUCH_DISTANCE
    assert r.value == pytest.approx(1.5e-3, abs=1e-5)


def test_a_start_grasp_out_of_closure_at_the_planning_friction_names_the_friction_it_needs(scene, turned):
    """Four fingers on the four side faces, above the centre, are in 6-D closure from mu 0.0031 (20 bisections):
    at scene mu 0.002 (mu_plan 0.0014) the start is refused with the friction it needs."""
    config = Config()
    low_friction = dataclasses.replace(config, scene=dataclasses.replace(config.scene, mu=0.002))
    with pytest.raises(StartRefused) as refused:
        space_start_root(scene, turned, low_friction)
    r = refused.value.refusal
    assert r.problem is StartProblem.NOT_IN_CLOSURE and r.value > r.limit == mu_plan(low_friction.scene, config.search)
    assert r.value == pytest.approx(0.0031, abs=1e-4)


def test_a_saved_start_plans_from_its_grasp_as_the_first_knot(tmp_path, capsys, scene, turned):
    out = tmp_path / "out"
    start = _write(tmp_path, turned.to_json())
    argv = ["plan", *SPACE, "--goal-rpy", "0", "0", "1", "--start", start, "--out", str(out), "--segment-workers", "1"]
    assert main(argv) == 0, capsys.readouterr().err
    report = json.loads((out / "plan.json").read_text())
    assert report["success"], report["status"]
    assert report["start"]["q"] == list(turned.q)
    with np.load(out / "plan.npz") as plan:
        np.testing.assert_allclose(plan["x"][0], turned.object_pose, atol=1e-9)
        np.testing.assert_allclose(plan["v"][0], 0.0, atol=1e-9)
        # the segment's IK puts each fingertip exactly on its contact: the search's IK had it within its tolerance
        q = np.reshape(turned.q, (4, 3))
        measured = np.array([f.fingertip(q[i]) for i, f in enumerate(scene.fingers)])
        assert np.max(np.linalg.norm(plan["p_W_tip"][0] - measured, axis=1)) < SPACE_TOUCH_DISTANCE
        np.testing.assert_allclose(plan["q"][0], turned.q, atol=0.01)
        goal = np.array([math.cos(0.5), 0.0, 0.0, math.sin(0.5)])
        assert quaternion_angle(plan["x"][-1, :4], goal) < math.radians(2.0)
    first = report["contact_plan"]["contact_sequence"][0]
    assert first["object_pose"] == pytest.approx(list(turned.object_pose))
    assert not np.allclose(turned.object_pose, START_POSE)  # a start other than the hand's own initial grasp
