"""The reproducers of issue items 6, 9 and 12 through the CLI: unbounded values, a long --out name
and --circle at its largest are answered before any work (exit 2, one line naming the value and its
range, nothing written) or accepted; a run's summary says "held" only when it ended within tolerance."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from trajectotree.cli import main

PLAN = ["plan", "--goal", "0.1", "--segments", "1"]


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def refused(args: list[str], capsys, folder: Path) -> str:
    """The one line `args` is refused with (exit 2), having written nothing into `folder`."""
    before = listing(folder)
    assert main(args) == 2, args
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured.err
    assert listing(folder) == before
    return captured.err.strip()


def test_unbounded_scene_values_are_refused_naming_the_range_in_a_subprocess(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "trajectotree.cli", *PLAN, "--mass", "1e308", "--out", str(tmp_path / "p")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr and out.stdout == ""
    assert out.stderr == (
        "trajectotree plan: error: --mass (scene.box_mass) = 1e+308 is out of range; valid range: [0.001, 10]\n"
    )
    assert listing(tmp_path) == []


@pytest.mark.parametrize(
    "field, message",
    [
        ("gravity", "scene.gravity = 1e+308 is out of range; valid range: (0, 100]"),
        ("box_depth", "scene.box_depth = 1e+308 is out of range; valid range: (0, 0.3]"),
    ],
)
def test_unbounded_config_values_are_refused_before_any_work(field, message, tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text(f"scene:\n  {field}: 1e308\n")
    line = refused([*PLAN, "--config", str(config), "--out", str(tmp_path / "p")], capsys, tmp_path)
    assert line == f"trajectotree plan: error: {message}"


@pytest.mark.parametrize(
    "option, value, message",
    [
        (
            "--tip-kp",
            "1e12",
            "--tip-kp (controller.grasp.tip_kp) = 1000000000000.0 is out of range; valid range: [0, 2000] N/m",
        ),
        ("--tip-kd", "7", "--tip-kd (controller.grasp.tip_kd) = 7.0 is out of range; valid range: [0, 5] N s/m"),
        (
            "--object-kd",
            "2000",
            "--object-kd (controller.grasp.object_kd) = 2000.0 is out of range; valid range: [0, 500] s^-1",
        ),
        ("--kv", "20", "--kv (controller.impedance.kv) = 20.0 is out of range; valid range: [0, 8] N s/m"),
        ("--sim-mass", "50", "--sim-mass = 50.0 is out of range; valid range: [0.001, 10]"),
    ],
)
def test_gains_beyond_what_the_discrete_loop_integrates_are_refused(
    option, value, message, tiny_plan, tmp_path, capsys
):
    plan = tmp_path / "plan"
    shutil.copytree(tiny_plan, plan)
    line = refused(["simulate", str(plan), option, value], capsys, tmp_path)
    assert line == f"trajectotree simulate: error: {message}"


def test_simulate_help_states_the_gains_ranges(capsys):
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "grasp controller: fingertip spring, N/m, in [0, 2000]" in text
    assert "the object's mass, kg, in [0.001, 10]" in text and "a disc of radius R m, in (0, 0.3]" in text


def test_an_out_name_longer_than_the_file_system_allows_is_refused(tmp_path, capsys):
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    long = "a" * 300
    line = refused([*PLAN, "--out", str(tmp_path / long)], capsys, tmp_path)
    assert line.endswith(f"a name in it is 300 bytes long; valid: at most {name_max} bytes per name (NAME_MAX of "
                         f"{str(tmp_path)!r})")  # fmt: skip
    assert line.startswith(f"trajectotree plan: error: --out {str(tmp_path / long)!r}")
    deep = tmp_path.joinpath(*["b" * 200] * 25)  # 5000 bytes
    line = refused([*PLAN, "--out", str(deep)], capsys, tmp_path)
    assert "bytes as an absolute path with the file plan.json in it; valid: at most" in line and "(PATH_MAX)" in line
    line = refused(["scene", "--figure", str(tmp_path / (long + ".png"))], capsys, tmp_path)
    assert line.startswith("trajectotree scene: error: --figure") and "a name in it is 304 bytes long" in line


def test_the_largest_disc_is_accepted(tmp_path, capsys):
    """--circle 0.3 is within (0, 0.3]: the search runs (the hand reaches no contact on so large a
    disc: a result with that reason, exit 0)."""
    assert main(["search", "--goal", "0.1", "--circle", "0.3"]) == 0
    out = capsys.readouterr().out
    assert "no plan" in out and "reach no corner-free contact" in out


def test_a_run_that_ends_on_its_plan_is_held_and_says_its_tolerance(tiny_plan, tmp_path, capsys):
    plan = tmp_path / "plan"
    shutil.copytree(tiny_plan, plan)
    assert main(["simulate", str(plan)]) == 0
    out = capsys.readouterr().out
    assert "box held (ended within 3 deg and 5 mm of the plan's final pose)" in out
    summary = json.loads((plan / "sim.json").read_text())
    assert summary["outcome"] == "held" and summary["within_tolerance"] is True and summary["dropped"] is False
    assert summary["divergence"] is None and summary["diverged_at_s"] is None
