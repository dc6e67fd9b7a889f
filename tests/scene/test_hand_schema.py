"""A hand description is read by the configuration's typed loader (HandYaml through
typed_yaml.load_typed): each refused key is named by its path in the file, with the file."""

from pathlib import Path

import pytest

from trajectotree.scene.hand import HandError, HandYaml, Plane, hand_file


def gripper_yaml(tmp_path: Path, old: str, new: str) -> Path:
    text = Path(hand_file("drake_planar_gripper").source).read_text()
    assert old in text
    path = tmp_path / "hand.yaml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("tip: finger2_tip_link,", "nail: finger2_tip_link,", "fingers[1].nail: unknown key; valid keys: ['joints', "),
        (
            "[finger1_BaseJoint, finger1_MidJoint]",
            "finger1_BaseJoint",
            "fingers[0].joints = 'finger1_BaseJoint' is not a list",
        ),
        ("x_axis: [0, 1, 0]", "x_axis: [0, .nan, 0]", "plane.x_axis = [0.0, nan, 0.0] is not a list of 3 finite"),
        ("mass: 0.028", "mass: heavy", "object.mass = 'heavy': "),
        ("\nfingers:", "\nthumbs: 1\nfingers:", "thumbs: unknown key; valid keys: ['model', 'plane', 'welds',"),
    ],
)
def test_a_refused_key_is_named_by_its_path_in_the_file(tmp_path, old, new, expected):
    path = gripper_yaml(tmp_path, old, new)
    with pytest.raises(HandError) as info:
        hand_file(str(path))
    assert str(info.value).startswith(f"hand {path}: ") and expected in str(info.value), str(info.value)


def test_the_built_in_descriptions_load_through_the_schema():
    gripper = hand_file("drake_planar_gripper")
    assert gripper.x_axis == (0.0, 1.0, 0.0) and len(gripper.welds) == 3 and gripper.object.mass == 0.028
    assert hand_file("planar_hand").x_axis == Plane().x_axis and HandYaml().fingers == ()
