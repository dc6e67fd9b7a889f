"""--hand through the command line: Drake's planar gripper's scene report, and descriptions that
must be refused (a missing joint, a finger with one joint, fewer than three fingers): exit 2,
the message naming the finger, the joint or the file, nothing written."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.common import FindResourceOrThrow

from trajectotree.cli import main
from trajectotree.scene.hand import hand_file, load_hand
from trajectotree.scene.kinematics import TwoLinkFinger

BRICK = ["--box-size", "0.1", "0.1", "--mass", "0.028"]  # Drake's planar_brick.sdf: 0.1 x 0.1 m in its plane, 28 g


def test_the_scene_command_reports_drakes_gripper(capsys):
    assert main(["scene", "--hand", "drake_planar_gripper", *BRICK, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert len(report["fingers"]) == 3 and report["num_actuators"] == 6 and report["tip_radius_m"] == 0.015
    assert [f["tau_max"] for f in report["fingers"]] == [[75.0, 75.0]] * 3
    reach = report["reach"]
    assert reach["graspable"] and reach["initial_grasps"] > 0 and len(reach["best_grasp_arclengths_m"]) == 3
    assert reach["workspace"]["every_orientation"]["points"] > 0


def gripper_yaml(tmp_path: Path, old: str, new: str) -> Path:
    text = Path(hand_file("drake_planar_gripper").source).read_text()
    assert old in text
    path = tmp_path / "hand.yaml"
    path.write_text(text.replace(old, new))
    return path


THIRD = "  - {joints: [finger3_BaseJoint, finger3_MidJoint], tip: finger3_tip_link, tip_xyz: [0, 0, -0.0263]}\n"


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("finger2_MidJoint]", "finger2_Knee]", "finger 1: its model .* has no joint 'finger2_Knee'"),
        ("[finger2_BaseJoint, finger2_MidJoint]", "[finger2_BaseJoint]", r"finger 1 has 1 joint\(s\)"),
        (THIRD, "", r"names 2 finger\(s\); a hand needs at least 3"),
    ],
)
def test_bad_hands_exit_2_naming_the_finger_and_write_nothing(tmp_path, capsys, old, new, expected):
    path = gripper_yaml(tmp_path, old, new)
    out = tmp_path / "plan"
    for args in (["scene", "--hand", str(path)], ["plan", "--goal", "0.3", "--hand", str(path), "--out", str(out)]):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert f"hand {path}: " in err and re.search(expected, err), err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["hand.yaml"]


@pytest.mark.parametrize(
    "hand, options, goal, fingers",
    [("drake_planar_gripper", BRICK, "0.3", 3), ("planar_hand5", [], "1.5", 5)],
)
def test_the_search_finds_contact_sequences_for_three_and_five_fingers(capsys, hand, options, goal, fingers):
    """The search's nodes touch the object where they say: each finger's joint angles put its
    fingertip sphere on its contact (FK of the hand's description), and at most one finger moves."""
    assert main(["search", "--hand", hand, *options, "--goal", goal, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["success"], result["reason"]
    description = load_hand(hand)
    stack = TwoLinkFinger.stack(description.fingers)
    previous = None
    for node in result["contact_sequence"]:
        x, y, theta = node["object_pose"]
        R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        tips = stack.fingertip(np.reshape(node["q"], (fingers, 2)))
        for tip, contact in zip(tips, node["contacts"], strict=True):
            target = np.array([x, y]) + R @ (
                np.array(contact["p_B"]) + description.tip_radius * np.array(contact["n_B"])
            )
            np.testing.assert_allclose(tip, target, atol=1e-5)  # Drake IK's 1e-6 m tolerance per axis
        arclengths = [c["arclength"] for c in node["contacts"]]
        if previous is not None:
            assert sum(a != b for a, b in zip(arclengths, previous)) <= 1
        previous = arclengths


@pytest.mark.slow  # two plans (CITO, keyframes), ~5-10 s each
@pytest.mark.parametrize("hand, options, fingers", [("drake_planar_gripper", BRICK, 3), ("planar_hand5", [], 5)])
def test_three_and_five_finger_hands_plan_and_pass_the_physics_check(tmp_path, capsys, hand, options, fingers):
    out = tmp_path / "plan"
    assert main(["plan", "--hand", hand, *options, "--goal", "0.3", "--segment-workers", "1", "--out", str(out)]) == 0
    result = json.loads((out / "plan.json").read_text())
    assert result["success"] and result["physics_check"]["passed"], result["physics_check"]["reason"]
    arrays = np.load(out / "plan.npz")
    assert arrays["q"].shape[1] == 2 * fingers and arrays["f_W"].shape[1:] == (fingers, 2)
    np.testing.assert_allclose(arrays["x"][-1], [0.0, 0.0, 0.3], atol=1e-6)


def test_a_hand_without_a_link_2_box_is_refused_before_planning(tmp_path, capsys):
    model = tmp_path / "gripper.sdf"
    text = Path(FindResourceOrThrow("drake/examples/planar_gripper/planar_gripper.sdf")).read_text()
    model.write_text(re.sub(r'<collision name="link2_collision">.*?</collision>', "", text, flags=re.S))
    yaml_text = Path(hand_file("drake_planar_gripper").source).read_text()
    (tmp_path / "gripper.yaml").write_text(
        yaml_text.replace("package://drake/examples/planar_gripper/planar_gripper.sdf", "gripper.sdf")
    )
    out = tmp_path / "plan"
    assert main(["plan", "--hand", str(model), *BRICK, "--goal", "0.3", "--out", str(out)]) == 2
    assert "has no collision box on finger 0's link 2" in capsys.readouterr().err
    assert not out.exists()


FIRST = "  - {joints: [finger1_BaseJoint, finger1_MidJoint], tip: finger1_tip_link, tip_xyz: [0, 0, -0.0263]}\n"


def test_a_hand_whose_joints_are_out_of_the_models_order_is_refused_execution(tmp_path, capsys):
    """The gripper with its first finger named last: it plans, but execution reads the plant's hand
    state as the planner's q, so demo and plan --html exit 2 before any work, writing nothing."""
    path = gripper_yaml(tmp_path, FIRST, "")
    path.write_text(path.read_text() + FIRST)
    for args in (
        ["demo", *BRICK, "--out", str(tmp_path / "demo")],
        ["plan", *BRICK, "--goal", "0.3", "--html", str(tmp_path / "p.html"), "--out", str(tmp_path / "plan")],
    ):
        assert main([*args, "--hand", str(path)]) == 2, args
        assert "needs the model's finger joints in the description's order" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hand.yaml"]


def test_a_hand_that_cannot_reach_the_object_is_refused_naming_the_finger(tmp_path, capsys):
    """Drake's gripper and a 0.28 m box: finger 2 (below it) reaches no corner-free contact."""
    out = tmp_path / "plan"
    assert (
        main(
            ["plan", "--hand", "drake_planar_gripper", "--box-size", "0.28", "0.28", "--goal", "0.3", "--out", str(out)]
        )
        == 2
    )
    assert "finger(s) [2] reach no corner-free contact at the initial pose" in capsys.readouterr().err
    assert not out.exists()


def test_the_gripper_holds_drakes_brick_unless_the_options_or_config_say_otherwise(tmp_path, capsys):
    def scene_object(*args):
        assert main(["scene", "--hand", "drake_planar_gripper", *args, "--json"]) == 0
        return json.loads(capsys.readouterr().out)["object"]

    brick = scene_object()
    assert (brick["size_m"], brick["mass_kg"], brick["mu"]) == ([0.1, 0.1], 0.028, 1.0)
    assert brick["inertia_zz_kg_m2"] == pytest.approx(1.17e-5)
    told = scene_object("--mass", "0.05", "--mu", "0.8")
    assert (told["size_m"], told["mass_kg"], told["mu"]) == ([0.1, 0.1], 0.05, 0.8)
    config = tmp_path / "c.yaml"
    config.write_text("scene: {mu: 0.6, box_width: 0.12}\n")
    filed = scene_object("--config", str(config))
    assert (filed["size_m"], filed["mass_kg"], filed["mu"]) == ([0.12, 0.1], 0.028, 0.6)
    assert filed["inertia_zz_kg_m2"] == pytest.approx(0.028 * (0.12**2 + 0.1**2) / 12)  # a uniform plate's
