"""Hand descriptions checked against their model before any work (trajectotree.scene.hand): every
moving joint of the model named by exactly one finger. The tester's YAML naming three of
planar_hand.sdf's four fingers planned (exit 0) and then crashed `simulate` (port sizes 16 vs 12);
now `plan`, `demo` and `simulate` refuse it with exit 2, one line, nothing written. A plan is
executed only with its own hand."""

import json
from pathlib import Path

import pytest

from trajectotree.cli import main
from trajectotree.io import SIM_JSON, SIM_NPZ
from trajectotree.scene.hand import HandError, hand_file, load_hand

PLANAR_HAND_SDF = Path(hand_file("planar_hand").model)
FINGER = "  - {{joints: [finger{i}_joint1, finger{i}_joint2], tip: finger{i}_tip}}\n"


def write_yaml(path: Path, fingers) -> Path:
    """A description of planar_hand.sdf naming `fingers` (indices, in order)."""
    path.write_text(f"model: {PLANAR_HAND_SDF}\nfingers:\n" + "".join(FINGER.format(i=i) for i in fingers))
    return path


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


ALL_JOINTS = str([f"finger{i}_joint{j}" for i in range(4) for j in (1, 2)])


@pytest.mark.parametrize(
    "fingers, message",
    [
        ((0, 1, 2), f"no finger names joint(s) ['finger3_joint1', 'finger3_joint2'] of its model {PLANAR_HAND_SDF}; "),
        ((0, 1, 2, 3, 3), "fingers 3 and 4 both name joint 'finger3_joint1'; each joint of the model belongs to one"),
        ((0, 1, 3, 2, 0), "fingers 0 and 4 both name joint 'finger0_joint1'"),
    ],
)
def test_plan_refuses_a_description_that_does_not_name_every_joint_once(tmp_path, capsys, fingers, message):
    hand = write_yaml(tmp_path / "hand.yaml", fingers)
    out = tmp_path / "plan"
    assert main(["plan", "--hand", str(hand), "--goal", "1", "--out", str(out)]) == 2
    line = one_line_error(capsys)
    assert f"hand {hand}: {message}" in line, line
    if "no finger names" in message:
        assert line.endswith(f"each of its moving joints must be one finger's: {ALL_JOINTS}")
    assert not out.exists()


def test_a_joint_named_twice_by_one_finger_is_refused(tmp_path):
    path = tmp_path / "hand.yaml"
    write_yaml(path, (0, 1, 2, 3))
    path.write_text(path.read_text().replace("[finger1_joint1, finger1_joint2]", "[finger1_joint1, finger1_joint1]"))
    with pytest.raises(HandError, match=r"finger 1 names joint 'finger1_joint1' twice"):
        hand_file(str(path))


def test_every_built_in_hand_names_each_of_its_joints_once():
    for name, joints in (("planar_hand", 8), ("planar_hand5", 10), ("drake_planar_gripper", 6)):
        hand = load_hand(name)
        assert len(set(hand.joint_names)) == hand.num_joints == joints


def test_demo_and_scene_refuse_the_three_finger_description_before_any_work(tmp_path, capsys):
    hand = write_yaml(tmp_path / "hand.yaml", (0, 1, 2))
    out = tmp_path / "demo"
    assert main(["demo", "--hand", str(hand), "--goal", "1", "--out", str(out)]) == 2
    assert "no finger names joint(s) ['finger3_joint1', 'finger3_joint2']" in one_line_error(capsys)
    assert not out.exists()
    assert main(["scene", "--hand", str(hand)]) == 2
    assert "no finger names joint(s)" in one_line_error(capsys)


@pytest.fixture(scope="module")
def file_hand_plan(tmp_path_factory):
    """A plan made with a four-finger description in a file of its own (the same hand as planar_hand)."""
    root = tmp_path_factory.mktemp("file_hand")
    hand = write_yaml(root / "hand.yaml", (0, 1, 2, 3))
    out = root / "plan"
    assert main(["plan", "--hand", str(hand), "--goal", "0.5", "--out", str(out)]) == 0
    assert json.loads((out / "plan.json").read_text())["success"]
    return hand, out


def test_simulate_refuses_a_plan_with_another_hand(file_hand_plan, capsys):
    hand, out = file_hand_plan
    capsys.readouterr()
    assert main(["simulate", str(out), "--hand", "planar_hand5"]) == 2
    line = one_line_error(capsys)
    assert f"scene.hand = 'planar_hand5' (the plan's: {str(hand)!r})" in line, line
    assert not (out / SIM_JSON).exists() and not (out / SIM_NPZ).exists()


def test_simulate_refuses_a_plan_whose_hand_file_now_names_three_fingers(file_hand_plan, tmp_path, capsys):
    hand, out = file_hand_plan
    capsys.readouterr()
    four = hand.read_text()
    try:
        write_yaml(hand, (0, 1, 2))
        assert main(["simulate", str(out)]) == 2
        assert "no finger names joint(s) ['finger3_joint1', 'finger3_joint2']" in one_line_error(capsys)
        assert not (out / SIM_JSON).exists() and not (out / SIM_NPZ).exists()
    finally:
        hand.write_text(four)
