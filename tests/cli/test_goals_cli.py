"""Goals on the command line: --goal-pose, a config file's goal, multi-turn goals and their
segments, the workspace `scene` reports, and a goal pose outside it (exit 2, nothing written)."""

import json
import math

from trajectotree.cli import main


def test_a_goal_pose_outside_the_workspace_exits_2_and_writes_nothing(tmp_path, capsys):
    assert main(["search", "--goal-pose", "0.2", "0", "0"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.startswith(
        "trajectotree search: error: --goal-pose X Y = (0.2, 0) m is outside the hand's workspace: along the path "
        "to it the hand has no grasp of the object at node "
    )
    assert "; valid: at most 0.1" in out.err and " m from the start (0, 0) m in this direction" in out.err
    assert main(["plan", "--goal-pose", "0", "-0.15", "1.0", "--out", str(tmp_path / "p")]) == 2
    assert "--goal-pose X Y = (0, -0.15) m is outside the hand's workspace" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_goal_poses_and_multi_turn_goals_plan_to_the_goal(capsys):
    assert main(["search", "--goal-pose", "0.02", "-0.01", "1.2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["success"] and data["goal"] == 1.2 and data["goal_position"] == [0.02, -0.01]
    assert len(data["contact_sequence"]) == 10 and data["contact_sequence"][-1]["object_pose"] == [0.02, -0.01, 1.2]
    # more than a full turn: 22 segments (-2 pi plans too, but in 10,000 expansions since the fingers are
    # kept apart: 20 s, near the search's 30 s budget on a loaded machine; 2 pi + 0.2 takes 1,200)
    full_turn = 2 * math.pi + 0.2
    assert main(["search", "--goal", str(full_turn), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["success"] and len(data["contact_sequence"]) == 23 and data["goal_position"] is None
    assert data["contact_sequence"][-1]["object_pose"][2] == full_turn
    assert main(["search", "--goal", str(full_turn), "--segments", "25"]) == 0  # --segments still decides
    assert ", N = 26: plan found" in capsys.readouterr().out


def test_a_config_files_goal_and_no_goal(tmp_path, capsys):
    config = tmp_path / "goal.yaml"
    config.write_text("goal:\n  theta: 0.5\n  position: [0.01, 0.0]\n")
    assert main(["search", "--config", str(config), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["goal"] == 0.5 and data["goal_position"] == [0.01, 0.0] and data["success"]
    assert main(["search", "--config", str(config), "--goal", "-0.4", "--json"]) == 0  # the option wins
    data = json.loads(capsys.readouterr().out)
    assert data["goal"] == -0.4 and data["goal_position"] is None
    config.write_text("goal:\n  theta: 70.0\n")
    assert main(["search", "--config", str(config)]) == 2
    assert "goal.theta = 70.0 is out of range; valid range: [-20 pi, 20 pi] rad" in capsys.readouterr().err
    assert main(["search"]) == 2
    assert "no goal: give --goal RAD, --goal-pose X Y THETA, or a goal section in --config" in capsys.readouterr().err


def test_scene_reports_the_workspace(capsys):
    assert main(["scene", "--json"]) == 0
    space = json.loads(capsys.readouterr().out)["reach"]["workspace"]
    every, start = space["every_orientation"], space["start_orientation"]
    assert space["grid_step_m"] == 0.01 and space["orientations"] == 36
    assert 0.02 < every["radius_m"] < start["radius_m"] and [0.0, 0.0] in every["translations_m"]
    assert main(["scene"]) == 0
    line = [t for t in capsys.readouterr().out.splitlines() if t.startswith("workspace: ")]
    assert (
        len(line) == 1 and f"at every orientation (every 10 deg of a turn) within {every['radius_m']:.3g} m" in line[0]
    )
