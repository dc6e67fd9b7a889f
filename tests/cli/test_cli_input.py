"""What a user types, through the command line: values with a minus sign, config files that are
no YAML or empty, a mass the motors cannot carry, the goal's bound in enough digits, a plan
folder whose files disagree, pushes after the run, long failure reasons and the demo's words.
Each test checks the exit code, the message and the files left."""

import json
import math
from pathlib import Path

from trajectotree.cli import main


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ---- the object's mass against what the hand can carry ------------------------------------------


def test_a_mass_the_motors_cannot_carry_is_refused_with_the_limit(tmp_path, capsys):
    (tmp_path / "heavy.yaml").write_text("scene:\n  box_mass: 4.0\n")
    option = "--mass (scene.box_mass) = "
    cases = [
        (["search", "--goal", "1.57", "--mass", "1e6", "--figure", str(tmp_path / "k.png")], option + "1000000.0 kg"),
        (["plan", "--goal", "1.57", "--mass", "5", "--out", str(tmp_path / "p")], option + "5.0 kg"),
        (["demo", "--mass", "3.3", "--out", str(tmp_path / "d")], option + "3.3 kg"),
        (["sweep", "--goals", "1", "--mass", "3.3", "--out", str(tmp_path / "s")], option + "3.3 kg"),
        (
            ["plan", "--goal", "1", "--config", str(tmp_path / "heavy.yaml"), "--out", str(tmp_path / "p")],
            "scene.box_mass = 4.0 kg",
        ),
    ]
    for args, value in cases:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert f"trajectotree {args[0]}: error: {value} is more than the hand can hold" in err, err
        assert "the strongest of the 2583 candidate initial grasps holds at most 3.22 kg" in err
        assert "3.22 kg at rest with four fingers" in err and "1 N m torque limit" in err, err
        assert err.rstrip().endswith("valid range: (0, 3.22] kg"), err
    assert listing(tmp_path) == ["heavy.yaml"]  # nothing written


def test_the_printed_mass_limit_is_accepted_and_a_stance_limit_warned(capsys):
    """3.22 kg is within the hold limit (3.226 kg, printed rounded down) but over what three fingers
    carry while the fourth switches (1.01 kg): a warning, and the search finds a plan that
    switches no finger (a 0.05 rad roll)."""
    assert main(["search", "--goal", "0.05", "--segments", "1", "--mass", "3.22", "--json"]) == 0
    captured = capsys.readouterr()
    assert "warning: --mass (scene.box_mass) = 3.22 kg is more than three fingers can hold while the fourth " in (
        captured.err
    )
    assert "at most 1.01 kg" in captured.err and "search.max_stance_force 10 N" in captured.err
    plan = json.loads(captured.out)
    assert plan["success"] and all(n["switching_finger"] is None for n in plan["contact_sequence"])
    assert main(["search", "--goal", "0.05", "--segments", "1", "--json"]) == 0  # 50 g: no warning
    assert capsys.readouterr().err == ""


def test_scene_states_the_payload(capsys):
    assert main(["scene", "--mass", "5"]) == 0  # scene reports, as for an object it cannot grasp
    out = capsys.readouterr().out
    assert "payload: the initial grasps hold at most 3.22 kg at rest, 1.01 kg while a finger lets go" in out
    assert "the hand CANNOT hold the object's 5 kg (planning refuses it)" in out
    assert main(["scene", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)["reach"]["payload"]
    assert payload["grasps"] == 2583 and math.isclose(payload["switch_kg"], 10 / 9.81)
