"""One typed loader for every hand description: the `kind` field (planar by default, or space)
read by hand_file's schema, the checks a hand in space gets, and each command refusing the other
kind with one line naming the hand and what takes it (exit 2, nothing written)."""

from pathlib import Path

import pytest

from trajectotree.scene.hand_file import (
    PLANAR,
    SPACE,
    HandError,
    HandYaml,
    hand_file,
    hand_kind,
    space_hand_file,
)
from trajectotree.scene.spatial import is_space_hand

FINGERPRO4 = Path(space_hand_file("fingerpro4").source)


def space_yaml(tmp_path: Path, old: str = "", new: str = "") -> Path:
    """fingerpro4.yaml copied to tmp_path (its model by absolute path), `old` replaced by `new`."""
    text = FINGERPRO4.read_text().replace("model: fingerpro4.sdf", f"model: {FINGERPRO4.with_suffix('.sdf')}")
    assert old in text
    path = tmp_path / "hand.yaml"
    path.write_text(text.replace(old, new))
    return path


def test_the_kind_is_planar_unless_the_file_says_space(tmp_path):
    assert HandYaml().kind == PLANAR
    assert hand_file("planar_hand").kind == PLANAR and hand_file("drake_planar_gripper").kind == PLANAR
    hand = space_hand_file("fingerpro4")
    assert hand.kind == SPACE and len(hand.fingers) == 4 and all(len(f.joints) == 3 for f in hand.fingers)
    assert hand.fingers[0].tip == "finger0_tip" and hand.object.size == (0.065, 0.065, 0.065)
    assert hand_kind(str(space_yaml(tmp_path))) == SPACE and is_space_hand(str(space_yaml(tmp_path)))
    assert not is_space_hand("planar_hand") and hand_kind(str(tmp_path / "missing.yaml")) == PLANAR


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("kind: space", "kind: spatial", "kind = 'spatial' is not one of ['planar', 'space']"),
        ("kind: space", "kind: space\nthumbs: 2", "thumbs: unknown key; valid keys: ['model', 'plane',"),
        ("  - {joints: [finger3_joint1, finger3_joint2, finger3_joint3], tip: finger3_tip}\n", "", "at least 4"),
        ("finger3_joint1, finger3_joint2, finger3_joint3", "finger3_joint1, finger3_joint2", "[2, 3] joints"),
        ("mass: 0.094}", "mass: 0.094}\nplane: {x_axis: [0, 1, 0], y_axis: [1, 0, 0]}", "takes no plane or welds"),
        ("size: [0.065, 0.065, 0.065]", "size: [0.065, 0.065]", "object.size = [0.065, 0.065] is not a list of 3"),
        ("size: [0.065, 0.065, 0.065]", "size: [0.065, 0.0, 0.065]", "is not a list of 3 positive numbers"),
        ("tip: finger1_tip}", "tip: finger1_tip, tip_xyz: [0, 0, 0.01]}", "takes its tip frame at the sphere"),
        ("finger2_joint1, finger2_joint2", "finger2_joint1, finger1_joint2", "both name joint 'finger1_joint2'"),
    ],
)
def test_a_hand_in_space_is_checked_by_the_typed_loader(tmp_path, old, new, expected):
    path = space_yaml(tmp_path, old, new)
    with pytest.raises(HandError) as info:
        space_hand_file(str(path))
    assert str(info.value).startswith(f"hand {path}: ") and expected in str(info.value), str(info.value)


def test_the_space_reader_refuses_a_planar_hand():
    with pytest.raises(HandError, match="hand planar_hand: is a planar hand"):
        space_hand_file("planar_hand")


@pytest.mark.parametrize("given_as", ["name", "file"])
def test_the_planar_path_refuses_a_hand_in_space_naming_it(tmp_path, given_as):
    # the Python API's planar planner reads its hand through hand_file, as every planar-only path does
    import trajectotree as tt

    hand = "fingerpro4" if given_as == "name" else str(space_yaml(tmp_path))
    with pytest.raises(HandError) as info:
        tt.plan(goal=0.5, config={"scene": {"hand": hand}})
    message = str(info.value)
    assert f"hand {hand}: is a hand in space (kind: space): only `trajectotree scene`, `search`, `plan`" in message
