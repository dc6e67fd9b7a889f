"""Executing a sweep's plans again per controller and robustness condition (trajectotree.experiments.executions)."""

import dataclasses
import json
import shutil

import pytest

from trajectotree.cli import main
from trajectotree.config import Config
from trajectotree.experiments.executions import ConditionSpec, execution_dir, middle_of_middle_segment


def test_push_starts_in_the_middle_of_the_middle_segment():
    config = Config()  # N = 10 nodes: 9 segments of 1.2 s; the middle one is segment 4, [4.8, 6.0] s
    assert middle_of_middle_segment(config, 10.8) == pytest.approx(5.4)
    three = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    assert middle_of_middle_segment(three, 2.4) == pytest.approx(1.8)
    kwargs = ConditionSpec().simulation_kwargs("mismatch", config, 10.8)
    assert kwargs == {"sim_mu": 0.55, "sim_mass": pytest.approx(1.2 * config.scene.box_mass)}


@pytest.mark.slow
def test_sweep_executes_every_plan_per_controller_and_condition(resumed_sweep, tmp_path, capsys):
    from conftest import SMALL_SWEEP

    out = tmp_path / "sweep"
    shutil.copytree(resumed_sweep.out, out)
    args = ["sweep", *SMALL_SWEEP, "--out", str(out), "--workers", "2"]
    assert main(args + ["--controllers", "grasp", "paper", "--conditions", "nominal", "push"]) == 0
    # 2 goals x 2 methods x 4 pairs, less the 4 grasp/nominal runs --simulate already made (copied)
    assert "executions: 12 run" in capsys.readouterr().out
    trials = sorted(p for p in (out / "trials").iterdir() if p.is_dir() and not p.name.startswith("."))
    assert len(trials) == 4
    for trial in trials:
        copied = execution_dir(trial, "grasp", "nominal") / "sim.json"
        assert copied.read_bytes() == (trial / "sim.json").read_bytes()
        for controller in ("grasp", "paper"):
            sim = json.loads((execution_dir(trial, controller, "push") / "sim.json").read_text())
            assert sim["controller"] == controller
            assert sim["conditions"]["push"] == {
                "force": [0.2, 0.0],
                "time_s": pytest.approx(1.8),
                "duration_s": pytest.approx(0.2),
            }
        paper = json.loads((execution_dir(trial, "paper", "nominal") / "sim.json").read_text())
        assert paper["controller"] == "paper" and paper["conditions"]["push"] is None
    assert main(args + ["--controllers", "grasp", "paper", "--conditions", "nominal", "push"]) == 0
    assert "executions: 0 run" in capsys.readouterr().out  # resumable: everything is there

    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report)]) == 0
    table = (report / "executions.md").read_text()
    for controller in ("grasp", "paper"):
        for condition in ("nominal", "push"):
            for method in ("TrajectoTree", "CITO, warm-start"):
                assert f"| {method} | {controller} | {condition} | 2 |" in table
        assert (report / f"fig3_tracking_{controller}.png").read_bytes()[:4] == b"\x89PNG"


def test_unknown_condition_exits_2_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", "--out", str(out), "--goals", "1", "--conditions", "earthquake", "--no-progress"]) == 2
    assert "condition = 'earthquake' is unknown" in capsys.readouterr().err
    assert not out.exists()
