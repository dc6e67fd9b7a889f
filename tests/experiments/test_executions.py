"""Executing a sweep's plans again per controller and robustness condition (trajectotree.experiments.executions)."""

import dataclasses
import functools
import json
import shutil

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, config_to_dict, with_values
from trajectotree.config.executor import Executor
from trajectotree.experiments.conditions import CONDITIONS, ConditionSpec, check_condition, middle_of_middle_segment
from trajectotree.experiments.execution_report import (
    execution_markdown,
    execution_summary,
    refused_markdown,
    refused_replans,
)
from trajectotree.experiments.executions import execution_dir, pending_executions, run_executions, torn_executions
from trajectotree.results import ReplanOutcome


def test_push_starts_in_the_middle_of_the_middle_segment():
    config = Config()  # N = 10 nodes: 9 segments of 1.2 s; the middle one is segment 4, [4.8, 6.0] s
    assert middle_of_middle_segment(config, 10.8) == pytest.approx(5.4)
    three = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    assert middle_of_middle_segment(three, 2.4) == pytest.approx(1.8)
    kwargs = ConditionSpec().simulation_kwargs("mismatch", config, 10.8)
    assert kwargs == {"sim_mu": 0.55, "sim_mass": pytest.approx(1.2 * config.scene.box_mass)}


def test_the_closed_loop_worlds_are_named_by_their_values():
    config = Config()
    spec = ConditionSpec()
    assert CONDITIONS == (
        "nominal",
        "mismatch",
        "push",
        "friction-0.4",
        "friction-0.3",
        "mass-x2",
        "push-3N",
        "push-6N",
    )
    assert spec.simulation_kwargs("friction-0.4", config, 10.8) == {"sim_mu": 0.4}
    assert spec.simulation_kwargs("friction-0.3", config, 10.8) == {"sim_mu": 0.3}
    assert spec.simulation_kwargs("mass-x2", config, 10.8) == {"sim_mass": pytest.approx(0.1)}
    assert spec.simulation_kwargs("nominal", config, 10.8) == {}
    for name, force in (("push-3N", 3.0), ("push-6N", 6.0)):
        push = spec.simulation_kwargs(name, config, 10.8)["push"]
        assert push.force == (force, 0.0) and push.time_s == pytest.approx(5.4) and push.duration_s == 0.2
    other = ConditionSpec(friction_mus=(0.5,), mass_factors=(1.5,), push_forces=(1.0,))
    assert tuple(other.worlds())[3:] == ("friction-0.5", "mass-x1.5", "push-1N")
    with pytest.raises(ConfigError, match="condition = 'friction-0.5' is unknown; valid: nominal, mismatch"):
        check_condition("friction-0.5")
    assert check_condition("friction-0.5", other) == "friction-0.5"
    with pytest.raises(ConfigError, match=r"friction_mus\[0\] = 0.0 is out of range"):
        ConditionSpec(friction_mus=(0.0,))


def write_trial(sweep_dir, key: str, config: Config, sim_json: dict | None):
    """A finished trial folder as the sweep leaves it: plan.json (a solved plan) and, when
    given, the sweep's own simulation (sim.json, sim.npz)."""
    trial = sweep_dir / "trials" / key
    trial.mkdir(parents=True)
    plan = {"method": "trajectotree", "iterations": 10, "config": config_to_dict(config)}
    (trial / "plan.json").write_text(json.dumps(plan))
    if sim_json is not None:
        (trial / "sim.json").write_text(json.dumps(sim_json))
        np.savez(trial / "sim.npz", t=np.zeros(2))
    return trial


def test_closed_loop_executions_are_their_own_and_never_copied(tmp_path):
    """The sweep's own (open-loop) nominal run stands in for the open-loop nominal execution,
    never for the closed loop's, which goes to exec/grasp-closed-loop_<condition>/."""
    config = Config()
    world = {"sim_mu": 0.7, "sim_mass": 0.05, "plan_mu": 0.7, "plan_mass": 0.05, "push": None}
    trial = write_trial(tmp_path, "t0", config, {"controller": "grasp", "conditions": world, "closed_loop": None})
    spec = ConditionSpec()
    closed = pending_executions(tmp_path, ["grasp-closed-loop"], ["nominal"], spec)
    assert [(t.executor, t.condition) for t in closed] == [(Executor.GRASP_CLOSED_LOOP, "nominal")]
    assert execution_dir(trial, Executor.GRASP_CLOSED_LOOP, "nominal") == trial / "exec" / "grasp-closed-loop_nominal"
    assert pending_executions(tmp_path, ["grasp"], ["nominal"], spec) == []  # copied from the sweep's run
    assert (trial / "exec" / "grasp_nominal" / "sim.json").is_file()
    assert not (trial / "exec" / "grasp-closed-loop_nominal").exists()
    with pytest.raises(ConfigError, match="executor = 'paper-closed-loop' is not an executor; valid: grasp, "):
        pending_executions(tmp_path, ["paper-closed-loop"], ["nominal"], spec)


@pytest.mark.slow
def test_sweep_executes_every_plan_per_controller_and_condition(resumed_sweep, tmp_path, capsys):
    from conftest import SMALL_SWEEP

    out = tmp_path / "sweep"
    shutil.copytree(resumed_sweep.out, out)
    args = ["sweep", *SMALL_SWEEP, "--out", str(out), "--workers", "2"]
    assert main(args + ["--controllers", "grasp", "paper", "--conditions", "push"]) == 0
    assert "executions: 8 run" in capsys.readouterr().out  # 2 goals x 2 methods x 2 controllers
    trials = sorted(p for p in (out / "trials").iterdir() if p.is_dir() and not p.name.startswith("."))
    assert len(trials) == 4
    for trial in trials:
        for controller in ("grasp", "paper"):
            sim = json.loads((execution_dir(trial, controller, "push") / "sim.json").read_text())
            assert sim["controller"] == controller
            assert sim["conditions"]["push"] == {
                "force": [0.2, 0.0],
                "time_s": pytest.approx(1.8),
                "duration_s": pytest.approx(0.2),
            }
    assert main(args + ["--controllers", "grasp", "paper", "--conditions", "push"]) == 0
    assert "executions: 0 run" in capsys.readouterr().out  # resumable: everything is there
    assert main(args + ["--controllers", "grasp", "--conditions", "nominal"]) == 0
    assert "executions: 0 run" in capsys.readouterr().out  # the open-loop nominal runs are the sweep's own
    for trial in trials:
        copied = execution_dir(trial, "grasp", "nominal") / "sim.json"
        assert copied.read_bytes() == (trial / "sim.json").read_bytes()

    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report)]) == 0
    table = (report / "executions.md").read_text()
    for controller, condition in (("grasp", "nominal"), ("grasp", "push"), ("paper", "push")):
        for method in ("TrajectoTree", "CITO, warm-start"):
            assert f"| {method} | {controller} | {condition} | 2 |" in table
    assert (report / "fig3_tracking_grasp.png").read_bytes()[:4] == b"\x89PNG"  # Fig. 3: the nominal runs


def test_unknown_condition_exits_2_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", "--out", str(out), "--goals", "1", "--conditions", "earthquake", "--no-progress"]) == 2
    assert "condition = 'earthquake' is unknown" in capsys.readouterr().err
    assert not out.exists()
    closed = ["sweep", "--out", str(out), "--goals", "1", "--no-progress", "--closed-loop"]
    assert main(closed + ["--controllers", "grasp", "paper"]) == 2
    err = capsys.readouterr().err
    assert "--controllers (controller) = 'paper': the closed loop runs around the grasp controller only" in err
    assert main(closed + ["--conditions", "friction-0.5"]) == 2
    assert "condition = 'friction-0.5' is unknown" in capsys.readouterr().err
    assert not out.exists()


def test_a_closed_loop_execution_beside_a_finished_open_loop_one_is_not_called_torn(tmp_path):
    """Pending closed-loop (and replanning) executions are judged by their own folders: a finished
    open-loop execution of the same condition is no torn one of theirs."""
    config = Config()
    trial = write_trial(tmp_path, "t0", config, None)
    done = execution_dir(trial, Executor.GRASP, "push-3N")
    done.mkdir(parents=True)
    (done / "sim.json").write_text(json.dumps({"dropped": False}))
    np.savez(done / "sim.npz", t=np.zeros(2))
    spec = ConditionSpec()
    assert pending_executions(tmp_path, ["grasp"], ["push-3N"], spec) == []
    for executor in (Executor.GRASP_CLOSED_LOOP, Executor.GRASP_REPLAN):
        tasks = pending_executions(tmp_path, [executor], ["push-3N"], spec)
        assert [t.folder.name for t in tasks] == [f"{executor.value}_push-3N"]
        assert torn_executions(tasks) == []
    torn = execution_dir(trial, Executor.GRASP_CLOSED_LOOP, "push-3N")
    torn.mkdir()
    (torn / "sim.json").write_text("{")
    tasks = pending_executions(tmp_path, ["grasp-closed-loop"], ["push-3N"], spec)
    (line,) = torn_executions(tasks)
    assert str(torn) in line and "unreadable" in line and line.endswith("it is recomputed")


def replan_record(goal: float, executor: str, dropped: bool, replans: list[dict]) -> dict:
    return {
        "method": "trajectotree",
        "goal": goal,
        "controller": executor,
        "condition": "friction-0.4",
        "dropped": dropped,
        "mae_x": 1e-3,
        "mae_y": 2e-3,
        "mae_theta": 0.01,
        "final_error": [1e-3, -2e-3, 0.1],
        "replans": replans,
    }


def test_the_report_sets_open_loop_closed_loop_and_replanning_side_by_side_with_the_refusals():
    refused = {
        "time_s": 2.4,
        "mu": 0.392,
        "latency_s": 0.15,
        "planned": False,
        "outcome": "no_plan",
        "status": "search failed: tree exhausted after 12 expansions",
    }
    planned = {"time_s": 3.6, "mu": 0.399, "latency_s": 0.61, "planned": True, "outcome": "planned", "status": "ok"}
    records = [
        replan_record(2.2, "grasp-replan", True, [refused]),
        replan_record(-2.61, "grasp-replan", False, [planned]),
        replan_record(2.2, "grasp", True, []),
        replan_record(2.2, "grasp-closed-loop", False, []),
    ]
    table = execution_summary(records, ["trajectotree"])
    assert [row["controller"] for row in table] == ["grasp", "grasp-closed-loop", "grasp-replan"]
    replanning = table[-1]
    assert (replanning["executed"], replanning["dropped"], replanning["replans"], replanning["new_plans"]) == (
        2,
        1,
        2,
        1,
    )
    assert replanning["latency_median_s"] == pytest.approx(0.38)
    assert replanning["latency_p95_s"] == pytest.approx(0.15 + 0.95 * 0.46)
    text = execution_markdown(table, {})
    assert "| trajectotree | grasp-replan | friction-0.4 | 2 | 1 (50%) |" in text
    assert "| 1.00 / 2.00, 0.100 | 0/2 | 2 (1) | 0.380 / 0.587 |" in text
    (row,) = refused_replans(records)
    assert (row["goal"], row["outcome"]) == (2.2, "no_plan")
    assert (
        "| trajectotree | +2.200 | friction-0.4 | 2.40 | 0.392 | no plan | "
        "search failed: tree exhausted after 12 expansions |" in refused_markdown([row], {})
    )


def test_a_replanning_sweep_around_another_controller_exits_2_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "sweep"
    replan = ["sweep", "--out", str(out), "--goals", "1", "--no-progress", "--replan"]
    assert main(replan + ["--controllers", "paper"]) == 2
    assert "--controllers (controller) = 'paper': the closed loop runs around the grasp controller only" in (
        capsys.readouterr().err
    )
    assert main(replan + ["--conditions", "friction-0.2"]) == 2
    assert "condition = 'friction-0.2' is unknown" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_open_loop_closed_loop_and_replanning_executions_side_by_side(resumed_sweep, tmp_path):
    """The same plans at friction 0.4 open loop, closed loop and replanning: executions.md lists the three per
    condition, with the replans, and sim.json records each replan's typed outcome. These plans have two
    segments: a replan at node 1 has no next node to plan from but the goal, so it plans from the measured
    state, for a tracking error past a threshold every run exceeds."""
    out = tmp_path / "sweep"
    shutil.copytree(resumed_sweep.out, out)
    # The cito-warm plans only, replanned by TrajectoTree (the command would execute every method's)
    run = functools.partial(run_executions, out, conditions=["friction-0.4"], methods=["cito-warm"], progress=False)
    tight = {"replan.theta_error": 1e-4, "replan.position_error": 1e-5, "replan.measured_start_on_error": True}
    gains = with_values(Config().controller, tight)
    assert run(executors=[Executor.GRASP, Executor.GRASP_CLOSED_LOOP], workers=2) == 4
    assert run(executors=[Executor.GRASP_REPLAN], workers=2, gains=gains) == 2
    trials = [out / "trials" / f"{i:04d}_cito-warm" for i in (0, 1)]
    closed = json.loads((execution_dir(trials[0], Executor.GRASP_CLOSED_LOOP, "friction-0.4") / "sim.json").read_text())
    assert closed["controller"] == "grasp" and closed["closed_loop"] is not None and closed["replans"] == []
    runs = [execution_dir(trial, Executor.GRASP_REPLAN, "friction-0.4") for trial in trials]
    replanned = [json.loads((folder / "sim.json").read_text()) for folder in runs]
    assert all(run["closed_loop"] is not None and run["conditions"]["sim_mu"] == 0.4 for run in replanned)
    events = [event for run in replanned for event in run["replans"]]
    assert events and all(event["reason"] == "tracking" for event in events)
    for event in events:
        assert event["outcome"] in {outcome.name.lower() for outcome in ReplanOutcome}
        assert event["latency_s"] > 0 and event["takes_effect_s"] == pytest.approx(event["time_s"] + event["latency_s"])
        assert event["start_s"] == event["time_s"]  # the measured state's
    report = tmp_path / "report"
    assert main(["report", str(out), "--out", str(report)]) == 0
    table, _, refused = (report / "executions.md").read_text().partition("## Replans without a plan")
    rows = [line for line in table.splitlines() if line.startswith("| CITO, warm-start |") and "friction-0.4" in line]
    assert [row.split(" | ")[1] for row in rows] == ["grasp", "grasp-closed-loop", "grasp-replan"], table
    assert "| TrajectoTree | grasp | friction-0.4 |" not in table  # not executed
    without = [e for e in events if not e["planned"]]
    assert all(e["status"].replace("|", "/") in refused for e in without), refused  # each one's reason, per goal
