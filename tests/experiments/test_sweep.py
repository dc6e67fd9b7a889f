"""The sweep: goals from a seed, trials in child processes (local or Dask), the resumable store."""

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, with_values
from trajectotree.experiments.sweep import SweepSpec, run_sweep, sample_goals
from trajectotree.experiments.sweep_store import MANIFEST_FILE, ROWS_FILE, TRIALS_DIR, prepare_dir, read_rows

# Small settings: 2 goals within +-0.3 rad, 2 transition segments.
SMALL = ["--goals", "2", "--seed", "0", "--max-goal", "0.3", "--segments", "2", "--no-progress"]


def small_spec(**changes) -> SweepSpec:
    config = Config()
    config = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    return SweepSpec(
        **{"goals": 2, "seed": 0, "methods": ("trajectotree",), "config": config, "max_goal": 0.3, **changes}
    )


def test_same_seed_gives_same_goals_in_range():
    a, b = sample_goals(60, 0), sample_goals(60, 0)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(a) <= math.pi) and a.std() > 1.0  # spread over [-pi, pi]
    assert not np.array_equal(a, sample_goals(60, 1))
    spec = SweepSpec(goals=60, seed=0)
    np.testing.assert_array_equal(spec.goal_values(), a)
    keys = [t.key for t in spec.tasks()]
    assert len(keys) == len(set(keys)) == 180 and keys[:3] == ["0000_trajectotree", "0000_cito", "0000_cito-warm"]


def test_importing_the_sweep_loads_no_drake():
    # The sweep's parent process only schedules trials (each plans in a child process or on a Dask
    # worker), so it stays light: config and results load Drake's YAML functions only when used.
    code = (
        "import sys, trajectotree.experiments.sweep; print(sorted(m for m in sys.modules if m.startswith('pydrake')))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--goals", "0"], "--goals = 0"),
        (["--workers", "-1"], "--workers = -1"),
        (["--methods", "trajectotree", "rrt"], "unknown method 'rrt'"),
        (["--time-limit", "0"], "--time-limit = 0"),
        (["--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "0.2"], "cannot reach the Dask scheduler"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "sweep"
    assert main(["sweep", "--out", str(out), "--goals", "2", "--no-progress"] + args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_rerun_with_different_arguments_is_an_error(tmp_path, capsys):
    out = tmp_path / "sweep"
    prepare_dir(out, small_spec())
    manifest = (out / MANIFEST_FILE).read_bytes()
    assert main(["sweep", "--out", str(out), *SMALL, "--methods", "trajectotree", "cito"]) == 2
    err = capsys.readouterr().err
    assert "different arguments" in err and "methods" in err
    assert main(["sweep", "--out", str(out), *SMALL, "--methods", "trajectotree", "--mu", "0.5"]) == 2
    assert "config.scene.mu: 0.7 there, 0.5 now" in capsys.readouterr().err
    assert (out / MANIFEST_FILE).read_bytes() == manifest
    with pytest.raises(ConfigError, match="non-empty directory"):
        run_sweep(small_spec(), tmp_path, progress=False)  # a directory that is not a sweep


def test_controller_settings_are_part_of_a_simulating_sweep_only(tmp_path):
    """A planning-only sweep's trials never read the controller or sim sections, so changing
    their defaults must not block resuming it; a sweep that simulates depends on them."""

    def with_gain(spec, kp):
        return dataclasses.replace(spec, config=with_values(spec.config, {"controller.impedance.kp": kp}))

    planning, simulating = tmp_path / "plan", tmp_path / "sim"
    prepare_dir(planning, small_spec())
    prepare_dir(simulating, small_spec(simulate=True))
    assert prepare_dir(planning, with_gain(small_spec(), 123.0)) == []
    with pytest.raises(ConfigError, match="config.controller.impedance.kp: 400.0 there, 123.0 now"):
        prepare_dir(simulating, with_gain(small_spec(simulate=True), 123.0))
    # resumed without --simulate: the difference is that flag (and the sections it records), not every setting
    with pytest.raises(ConfigError) as refused:
        prepare_dir(simulating, small_spec())
    differences = str(refused.value).split("different arguments (")[1].split("); rerun")[0].split("; ")
    assert "simulate: True there, False now" in differences
    assert [d.split(":")[0] for d in differences] == ["config.controller", "config.sim", "simulate"]
    assert differences[0].startswith("config.controller: a section of ") and differences[0].endswith("there, None now")


@pytest.mark.slow
def test_killed_sweep_reruns_only_unfinished_trials(resumed_sweep):
    out, before = resumed_sweep.out, resumed_sweep.before
    assert resumed_sweep.rerun.returncode == 0, resumed_sweep.rerun.stderr
    keys = [t.key for t in SweepSpec(goals=2, seed=0, methods=("trajectotree", "cito-warm")).tasks()]
    assert 1 <= len(before) < len(keys)  # killed mid-way
    assert f"{len(keys) - len(before)} now, {len(before)} before" in resumed_sweep.rerun.stdout
    after = {d.name: d for d in (out / TRIALS_DIR).iterdir()}
    assert sorted(after) == sorted(keys)
    for key, files in before.items():  # finished trials were not recomputed, not even rewritten
        assert {
            f.name: (f.stat().st_ino, f.stat().st_mtime_ns, f.stat().st_size) for f in after[key].iterdir()
        } == files
    assert not [p for p in out.rglob("*") if p.name.startswith(".tmp-")]
    rows = [json.loads(line) for line in (out / ROWS_FILE).read_text().splitlines()]
    assert sorted(r["key"] for r in rows) == sorted(keys) and rows == read_rows(out)
    for row in rows:  # every file is complete and agrees with the row
        assert row["error"] is None
        trial = out / TRIALS_DIR / row["key"]
        plan_json = json.loads((trial / "plan.json").read_text())
        assert (plan_json["method"], plan_json["success"], plan_json["total_time_s"]) == (
            row["method"],
            row["success"],
            row["total_time_s"],
        )
        with np.load(trial / "plan.npz") as npz:
            arrays = {name: npz[name] for name in npz.files}
        if row["simulated"]:
            assert arrays["x"].shape[1] == 3 and np.all(np.isfinite(arrays["x"]))
            sim_json = json.loads((trial / "sim.json").read_text())
            with np.load(trial / "sim.npz") as npz:
                assert npz["abs_error"].shape == (npz["t"].size, 3)
            assert sim_json["mae_theta"] == row["mae_theta"]


@pytest.mark.slow
def test_trials_follow_the_seed(resumed_sweep):
    """The manifest's goals come from the seed, and each trial's contact sequence is the
    one the contact search finds for that goal (run here, in this process)."""
    from trajectotree.config import config_from_dict
    from trajectotree.scene.plant import build_scene
    from trajectotree.search.tree import find_contact_plan

    manifest = json.loads((resumed_sweep.out / MANIFEST_FILE).read_text())
    np.testing.assert_array_equal(manifest["goal_values"], sample_goals(2, 0, 0.3))
    config = config_from_dict(manifest["config"])
    scene = build_scene(config.scene)
    for row in read_rows(resumed_sweep.out):
        if row["method"] != "trajectotree":
            continue
        plan_json = json.loads((resumed_sweep.out / TRIALS_DIR / row["key"] / "plan.json").read_text())
        expected = find_contact_plan(scene, row["goal"], config.search)
        assert plan_json["search"]["success"] == expected.success
        assert row["switching_fingers"] == [n.switching_finger for n in expected.nodes]
        for node, saved in zip(expected.nodes, plan_json["contact_sequence"]):
            np.testing.assert_allclose([c["arclength"] for c in saved["contacts"]], node.arclengths, atol=1e-12)
            np.testing.assert_allclose(saved["q"], node.q, atol=1e-9)


@pytest.mark.slow
def test_dask_cluster_gives_the_same_trials(tmp_path):
    from distributed import LocalCluster

    spec = small_spec()
    local = run_sweep(spec, tmp_path / "local", workers=2, progress=False)
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, protocol="tcp", host="127.0.0.1", dashboard_address=None
    ) as cluster:
        remote = run_sweep(spec, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    assert local.ran == remote.ran == 2 and local.errors == remote.errors == 0
    local_rows = {r["key"]: r for r in read_rows(tmp_path / "local")}
    for row in read_rows(tmp_path / "dask"):
        mine = local_rows[row["key"]]
        for field in ("goal", "success", "status", "iterations", "switching_fingers", "cost"):
            assert row[field] == mine[field], field
        plans = [
            json.loads((tmp_path / d / TRIALS_DIR / row["key"] / "plan.json").read_text()) for d in ("local", "dask")
        ]
        assert plans[0]["contact_sequence"] == plans[1]["contact_sequence"]
        arrays = []
        for d in ("local", "dask"):
            with np.load(tmp_path / d / TRIALS_DIR / row["key"] / "plan.npz") as npz:
                arrays.append({name: npz[name] for name in npz.files})
        assert arrays[0].keys() == arrays[1].keys()
        for name in arrays[0]:
            np.testing.assert_array_equal(arrays[0][name], arrays[1][name], err_msg=name)


@pytest.mark.slow
def test_failing_trials_are_recorded_and_the_sweep_goes_on(tmp_path):
    from trajectotree.experiments.trial import execute_trial

    # Past its time limit: the child is killed; the sweep records both trials and finishes.
    summary = run_sweep(small_spec(time_limit_s=0.2), tmp_path / "limit", workers=2, progress=False)
    rows = read_rows(tmp_path / "limit")
    assert summary.ran == 2 and summary.errors == 2 and len(rows) == 2
    assert all(r["error"].startswith("timeout: exceeded the trial time limit of 0.2 s") for r in rows)
    again = run_sweep(small_spec(time_limit_s=0.2), tmp_path / "limit", workers=2, progress=False)
    assert (again.ran, again.skipped) == (0, 2)
    retried = run_sweep(small_spec(time_limit_s=0.2), tmp_path / "limit", workers=2, progress=False, retry_errors=True)
    assert (retried.ran, retried.skipped) == (2, 0)
    # A trial that raises (a goal the planner rejects) is a row with the exception's message.
    task = small_spec().tasks()[0]
    outcome = execute_trial(dataclasses.replace(task, goal=float("nan")))
    assert outcome.row["error"].endswith(
        "ConfigError: goal = nan is out of range; valid range: [-20 pi, 20 pi] rad, 20 pi = 62.83185307"
    )
    assert outcome.row["success"] is None
    assert "Traceback" in outcome.files["log.txt"].decode()


def test_library_sweep_into_a_file_is_an_input_error(tmp_path):
    a_file = tmp_path / "sweep"
    a_file.write_text("not a sweep")
    with pytest.raises(ConfigError, match="is an existing file, not a folder"):
        run_sweep(small_spec(), a_file, progress=False)
    assert a_file.read_text() == "not a sweep"
