"""`trajectotree sweep` and `report` with a hand in space (issue #36 item 6): goal orientations uniform over SO(3),
each planned in its own trial process and stored as the planar sweep stores its trials (resumable), the report's
summary per method; bad input and the execution options (issue #37) exit 2 naming the value before anything is
written."""

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from trajectotree.cli import main
from trajectotree.experiments.sweep import sample_space_goals

SPACE = ["--hand", "fingerpro4"]
# 1 goal at most 0.3 rad (17 deg) from the start: it plans in about 2 s on one core (CITO warm-started: more)
SMALL = ["--goals", "1", "--seed", "0", "--max-goal", "0.3", "--methods", "trajectotree", "cito-warm"]


def test_goals_are_scipys_uniform_rotations_and_max_goal_bounds_their_angle():
    default = sample_space_goals(5, 3)
    assert np.array_equal(default, Rotation.random(5, random_state=3).as_quat(scalar_first=True))
    near = sample_space_goals(4, 3, 0.3)
    angles = Rotation.from_quat(near, scalar_first=True).magnitude()
    assert near.shape == (4, 4) and np.all(angles <= 0.3) and np.all(angles > 0.0)
    assert np.array_equal(near, sample_space_goals(4, 3, 0.3))  # the seed decides them


def _argv(out, *extra) -> list[str]:
    return ["sweep", *SPACE, *SMALL, "--workers", "2", "--no-progress", "--out", str(out), *extra]


@pytest.mark.slow
def test_sweep_in_space_plans_resumes_and_reports(tmp_path, capsys):
    """Every command through the CLI's main in this process (an interpreter's start-up, 1-2 s, less each), each
    trial in a process of its own as the sweep runs them."""
    out = tmp_path / "sweep"
    assert main(_argv(out)) == 0
    assert "2/2 trials done (2 now, 0 before)" in capsys.readouterr().out
    manifest = json.loads((out / "manifest.json").read_text())
    goals = np.array(manifest["goal_values"])
    assert manifest["space"] == {"size": None, "mass": None} and goals.shape == (1, 4)
    assert np.allclose(goals, sample_space_goals(1, 0, 0.3))
    for key in ("0000_trajectotree", "0000_cito-warm"):
        folder = out / "trials" / key
        row = json.loads((folder / "trial.json").read_text())
        plan = json.loads((folder / "plan.json").read_text())
        assert plan["kind"] == "space" and plan["method"] == key[5:]
        assert np.allclose(row["goal"], plan["goal_quaternion"])
        assert row["plan_arrays"] == (folder / "plan.npz").is_file()
        assert row["check_passed"] == plan["physics_check"]["passed"]
        assert row["final_error_deg"] == pytest.approx(math.degrees(plan["final_error_rad"]))
        assert row["success"] == plan["success"] and row["total_time_s"] == plan["total_time_s"]
    tree_row = json.loads((out / "trials" / "0000_trajectotree" / "trial.json").read_text())
    assert tree_row["success"] and tree_row["check_passed"] and tree_row["final_error_deg"] <= 2.0

    assert main(_argv(out)) == 0  # resumed: every trial finished, none rerun
    assert "2/2 trials done (0 now, 2 before)" in capsys.readouterr().out
    assert json.loads((out / "trials" / "0000_trajectotree" / "trial.json").read_text()) == tree_row

    assert main(_argv(out, "--mass", "0.05")) == 2  # another box is another sweep: refused, nothing touched
    assert "space.mass: None there, 0.05 now" in capsys.readouterr().err

    assert main(["report", str(out)]) == 0
    summary = (out / "report" / "summary.md").read_text()
    assert "| TrajectoTree | 1 | 0 | 1/1 | 1/1 | 1/1 |" in summary
    assert "are not drawn for a\nsweep in space" in summary
    csv_lines = (out / "report" / "summary.csv").read_text().splitlines()
    assert csv_lines[0].split(",")[:7] == ["method", "label", "trials", "errors", "planned", "checked", "within_2_deg"]
    assert [line.split(",")[0] for line in csv_lines[1:]] == ["trajectotree", "cito-warm"]
    ratio = float(csv_lines[2].split(",")[-1])  # cito-warm's median over TrajectoTree's, from the trials' times
    times = {
        m: json.loads((out / "trials" / f"0000_{m}" / "trial.json").read_text())["total_time_s"]
        for m in ("trajectotree", "cito-warm")
    }
    assert ratio == pytest.approx(times["cito-warm"] / times["trajectotree"])
    assert not list((out / "report").glob("*.png"))


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--controllers", "paper"], "--controllers paper: the executor 'paper' does not execute"),
        (["--conditions", "push-6N"], "condition = 'push-6N' is unknown"),
        (["--max-goal", "4"], "--max-goal"),
        (["--goals", "0"], "--goals"),
        (["--methods", "rrt"], "--methods: unknown method 'rrt'"),
        (["--box-size", "0.06", "0.06"], "--box-size = [0.06, 0.06] has 2 values; the hand 'fingerpro4' is in space"),
        (["--box-size", "0.3", "0.3", "0.3"], "--box-size = 0.3 0.3 0.3 m"),
        (["--segments", "3"], "--segments = 3 is a planar hand's option; the hand 'fingerpro4' is in space"),
    ],
)
def test_bad_input_exits_2_naming_it_and_writes_nothing(tmp_path, capsys, extra, message):
    out = tmp_path / "sweep"
    assert main(["sweep", *SPACE, "--goals", "2", "--out", str(out), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trajectotree sweep: error: ") and message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()
