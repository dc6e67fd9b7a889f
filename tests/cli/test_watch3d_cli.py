"""Bad input to watching a run in space stays exit 2 with one line naming the value, before any planning or
simulation and with nothing written: `demo` with a goal of the other kind than its hand's, a goal out of range, a
controller space does not have yet, an --out that is a file; `simulate` of a plan in space with a playback file
of the wrong kind (the plan folder left as it was)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from trajectotree.cli import main

SPACE_DEMO = ["demo", "--hand", "fingerpro4"]


def _refused(argv, capsys) -> str:
    """The one line `argv` exits 2 with."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "Traceback" not in captured.err
    return captured.err


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--goal", "1.0"], "--goal = 1.0 is a planar goal"),
        (["--goal-rpy", "nan", "0", "0"], "--goal-rpy"),
        (["--goal-rpy", "200", "0", "0"], "--goal-rpy"),
        (["--goal-quat", "0", "0", "0", "0"], "--goal-quat"),
    ],
)
def test_a_space_demo_with_a_bad_goal_exits_2_writing_nothing(tmp_path, capsys, extra, named):
    out = tmp_path / "demo"
    err = _refused([*SPACE_DEMO, *extra, "--out", str(out)], capsys)
    assert named in err
    assert not out.exists()


def test_a_space_goal_with_the_planar_demo_exits_2(tmp_path, capsys):
    out = tmp_path / "demo"
    err = _refused(["demo", "--goal-rpy", "0.6", "0", "0", "--out", str(out)], capsys)
    assert "--goal-rpy" in err and "is planar" in err
    assert not out.exists()


def test_a_space_demo_with_a_controller_space_does_not_have_exits_2(tmp_path, capsys):
    config = tmp_path / "paper.yaml"
    config.write_text("sim: {controller: paper}\n")
    out = tmp_path / "demo"
    err = _refused([*SPACE_DEMO, "--config", str(config), "--out", str(out)], capsys)
    assert "sim.controller" in err and "'paper'" in err and "grasp" in err
    assert not out.exists()


def test_a_space_demo_into_a_file_exits_2(tmp_path, capsys):
    out = tmp_path / "demo"
    out.write_text("not a folder")
    err = _refused([*SPACE_DEMO, "--out", str(out)], capsys)
    assert "--out" in err and "is an existing file" in err
    assert out.read_text() == "not a folder"


@pytest.mark.slow  # one plan in space, ~5 s
@pytest.mark.parametrize(
    "option, name",
    [("--html", "run.txt"), ("--gif", "run.png"), ("--forces", "forces.gif")],
)
def test_simulate_of_a_plan_in_space_with_a_playback_file_of_the_wrong_kind_exits_2(
    shared_space_plan, tmp_path, capsys, option, name
):
    folder = tmp_path / "plan"
    shutil.copytree(shared_space_plan, folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    err = _refused(["simulate", str(folder), option, str(tmp_path / name)], capsys)
    assert option in err and name in err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # no sim.json, sim.npz
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan"]


@pytest.fixture(scope="module")
def shared_space_plan(space_plan) -> Path:
    """conftest's plan folder in space (plan.json, plan.npz) of a 34 deg turn, shared: the tests copy it."""
    assert json.loads((space_plan / "plan.json").read_text())["success"]
    with np.load(space_plan / "plan.npz") as npz:
        assert npz["x"].shape[1] == 7
    return space_plan
