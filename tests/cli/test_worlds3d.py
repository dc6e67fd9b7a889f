"""Worlds, sweeps and reports in space (issue #37 items 4-5): `simulate` of a plan in space under another friction,
mass and a 3-component push; `sweep --hand fingerpro4 --simulate` and `--conditions` executing each plan open loop
in the worlds of conditions.SPACE_SPEC, resumably; the report's table and figure of those executions; bad input
exits 2 naming it, writing nothing."""

import contextlib
import io
import json
import shutil

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError
from trajectotree.execution.world import Conditions, Push, parse_push
from trajectotree.experiments.conditions import CONDITIONS, SPACE_CONDITIONS, SPACE_SPEC
from trajectotree.experiments.sweep import SpaceSweepObject, SweepSpec, axis_aligned_goals

SPACE = ["--hand", "fingerpro4"]
# 2 goals at most 0.3 rad from the start (each plans in about 2 s and runs 1.5 s), planned and executed open loop,
# then again under a 1 N horizontal push
SWEEP = ["--goals", "2", "--max-goal", "0.3", "--methods", "trajectotree", "--simulate", "--workers", "1"]


def test_a_push_in_space_has_three_components_and_the_plane_keeps_two():
    push = parse_push("1,0,-0.5@2.5", 0.2, components=3)
    assert push == Push(force=(1.0, 0.0, -0.5), time_s=2.5, duration_s=0.2)
    with pytest.raises(ConfigError, match=r"push '1,0@2.5' is not FX,FY,FZ@T \(a plan in space is pushed in 3D"):
        parse_push("1,0@2.5", components=3)
    with pytest.raises(ConfigError, match=r"push '1,0,0@2.5' is not FX,FY@T \(force in N in W"):
        parse_push("1,0,0@2.5")
    assert parse_push("0.2,0@3.5").force == (0.2, 0.0)


def test_space_worlds_scale_the_cube_and_push_horizontally_mid_segment():
    """The issue's three worlds beside the shared ones; the plane's names as they were."""
    assert SPACE_CONDITIONS == ("nominal", "mismatch", "push", "friction-0.4", "mass-x1.5", "push-1N")
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
    config = Config()
    assert SPACE_SPEC.space_world("friction-0.4", config, 0.094, 5.0, 5) == Conditions(mu=0.4)
    assert SPACE_SPEC.space_world("mass-x1.5", config, 0.094, 5.0, 5).mass == pytest.approx(0.141)
    push = SPACE_SPEC.space_world("push-1N", config, 0.094, 5.0, 5).push
    # 5 segments of 1 s: the middle one is [2, 3) s; its middle 2.5 s
    assert push == Push(force=(1.0, 0.0, 0.0), time_s=2.5, duration_s=config.sim.push_duration)
    with pytest.raises(ConfigError, match="condition = 'push-6N' is unknown"):
        SPACE_SPEC.space_world("push-6N", config, 0.094, 5.0, 5)


def test_world_json_names_the_simulated_and_planned_values():
    world = Conditions(mu=0.4, push=Push(force=(1.0, 0.0, 0.0), time_s=0.5)).world_json(0.7, 0.094)
    assert world == {
        "sim_mu": 0.4,
        "sim_mass": 0.094,
        "plan_mu": 0.7,
        "plan_mass": 0.094,
        "push": {"force": [1.0, 0.0, 0.0], "time_s": 0.5, "duration_s": 0.2},
    }


def test_axis_aligned_goals_are_the_first_of_the_23():
    spec = SweepSpec(goals=3, seed=0, methods=("trajectotree",), space=SpaceSweepObject(), axis_aligned=True)
    assert np.array_equal(spec.goal_values(), axis_aligned_goals()[:3])
    assert spec.manifest()["axis_aligned"] is True
    assert "axis_aligned" not in SweepSpec(goals=3, seed=0, space=SpaceSweepObject()).manifest()


@pytest.mark.parametrize(
    "argv, message",
    [
        ([*SPACE, "--conditions", "push-6N"], "condition = 'push-6N' is unknown; valid: nominal, mismatch, push, "),
        (
            [*SPACE, "--controllers", "paper"],
            "--controllers paper: the executor 'paper' does not execute plans in space",
        ),
        ([*SPACE, "--axis-aligned", "--goals", "24"], "--goals = 24 is out of range; valid range: [1, 23]"),
        (["--axis-aligned"], "--axis-aligned: the axis-aligned orientations are goals of a hand in space"),
    ],
)
def test_bad_sweep_input_exits_2_naming_it_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "sweep"
    assert main(["sweep", *argv, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trajectotree sweep: error: ") and message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.fixture(scope="module")
def space_sweep(tmp_path_factory):
    """A 2-goal sweep in space, executed open loop and under push-1N (about 30 s on the loaded 2 cores)."""
    out = tmp_path_factory.mktemp("worlds3d") / "sweep"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):  # the CLI's main in this process, each trial in its own
        code = main(["sweep", *SPACE, *SWEEP, "--conditions", "push-1N", "--no-progress", "--out", str(out)])
    assert code == 0
    done = printed.getvalue()
    assert "2/2 trials done (2 now, 0 before)" in done and "executions: 2 run (grasp x push-1N)" in done
    return out


@pytest.mark.slow
def test_a_sweep_in_space_executes_each_plan_in_its_worlds(space_sweep):
    for key in ("0000_trajectotree", "0001_trajectotree"):
        trial = space_sweep / "trials" / key
        row = json.loads((trial / "trial.json").read_text())
        sim = json.loads((trial / "sim.json").read_text())
        assert row["simulated"] and row["dropped"] == sim["dropped"] is False
        assert (
            row["within_15deg"] == sim["within_15deg"]
            and row["final_position_error_m"] == sim["final_position_error_m"]
        )
        with np.load(trial / "plan.npz") as plan, np.load(trial / "sim.npz") as run:
            K, F = len(run["t"]), plan["f_W"].shape[1]
            assert run["x"].shape == run["x_plan"].shape == (K, 7) and run["f_W"].shape == (K, F, 3)
            assert run["q"].shape == (K, plan["q"].shape[1])
            nominal_x = run["x"]
        pushed = trial / "exec" / "grasp_push-1N"
        world = json.loads((pushed / "sim.json").read_text())["conditions"]
        plan = json.loads((trial / "plan.json").read_text())
        segments = len(plan["contact_plan"]["contact_sequence"]) - 1
        with np.load(trial / "plan.npz") as arrays:
            duration = float(arrays["t"][-1])
        start = (segments // 2 + 0.5) * duration / segments  # the middle of the middle segment
        assert world["push"] == {"force": [1.0, 0.0, 0.0], "time_s": pytest.approx(start), "duration_s": 0.2}
        assert world["sim_mu"] == world["plan_mu"] and world["sim_mass"] == world["plan_mass"]
        with np.load(pushed / "sim.npz") as run:
            t, x = run["t"], run["x"]
        before, after = t < start, t > start + 0.2
        np.testing.assert_array_equal(x[before], nominal_x[before])  # the same run until the push
        assert np.abs(x[after, 4] - nominal_x[after, 4]).max() > 1e-4  # then the cube moves along x


@pytest.mark.slow
def test_a_resumed_sweep_in_space_runs_no_finished_execution_and_reports(space_sweep, capsys):
    """The resumed sweep and the report through the CLI's main in this process, as the sweep itself."""
    pushed = space_sweep / "trials" / "0000_trajectotree" / "exec" / "grasp_push-1N" / "sim.json"
    before = pushed.stat().st_mtime_ns
    argv = ["sweep", *SPACE, *SWEEP, "--conditions", "push-1N", "nominal", "--no-progress", "--out", str(space_sweep)]
    assert main(argv) == 0
    again = capsys.readouterr().out
    # nothing planned again; push-1N finished; nominal is the trial's own run, copied
    assert "2/2 trials done (0 now, 2 before)" in again and "executions: 0 run" in again
    assert pushed.stat().st_mtime_ns == before
    trial = space_sweep / "trials" / "0000_trajectotree"
    assert (trial / "exec" / "grasp_nominal" / "sim.json").read_bytes() == (trial / "sim.json").read_bytes()

    assert main(["report", str(space_sweep)]) == 0
    report = capsys.readouterr().out
    assert "executions: " in report and "fig_final_error.png" in report
    folder = space_sweep / "report"
    assert (folder / "fig_final_error.png").stat().st_size > 0 and (folder / "fig_final_error.pdf").is_file()
    table = (folder / "executions.md").read_text()
    lines = (folder / "executions.csv").read_text().splitlines()
    header = lines[0].split(",")
    rows = {(r[1], r[2]): dict(zip(header, r)) for r in (line.split(",") for line in lines[1:])}
    assert set(rows) == {("grasp", "nominal"), ("grasp", "push-1N")}  # nominal once: the copy is the trial's run
    for condition in ("nominal", "push-1N"):
        runs = [
            json.loads(
                (
                    space_sweep / "trials" / f"000{i}_trajectotree" / "exec" / f"grasp_{condition}" / "sim.json"
                ).read_text()
            )
            for i in (0, 1)
        ]
        row = rows[("grasp", condition)]
        assert int(row["executed"]) == 2 and int(row["dropped"]) == sum(r["dropped"] for r in runs)
        assert int(row["within_15deg"]) == sum(r["within_15deg"] for r in runs)
        held = [r for r in runs if not r["dropped"]]
        assert float(row["mean_final_orientation_error_deg"]) == pytest.approx(
            np.mean([r["final_orientation_error_deg"] for r in held])
        )
        assert float(row["mean_final_position_error_mm"]) == pytest.approx(
            np.mean([1e3 * r["final_position_error_m"] for r in held])
        )
        assert f"| TrajectoTree | grasp | {condition} | 2 | {row['dropped']} (" in table


@pytest.mark.slow
def test_simulate_in_space_takes_another_world_and_refuses_a_planar_push(space_sweep, tmp_path, capsys):
    plan = tmp_path / "plan"
    plan.mkdir()
    for name in ("plan.json", "plan.npz"):
        shutil.copy(space_sweep / "trials" / "0000_trajectotree" / name, plan / name)
    for bad, named in (
        (["--push", "1,0@0.5"], "push '1,0@0.5' is not FX,FY,FZ@T (a plan in space is pushed in 3D"),
        (["--push", "1,0,0@9"], "--push '1,0,0@9' starts at 9 s, when the run is over"),
        (["--sim-mu", "0"], "--sim-mu = 0.0 is out of range; valid range: (0, 5]"),
    ):
        assert main(["simulate", str(plan), *bad]) == 2
        err = capsys.readouterr().err
        assert named in err and "Traceback" not in err
        assert sorted(p.name for p in plan.iterdir()) == ["plan.json", "plan.npz"]  # nothing written, no lock left
    argv = ["simulate", str(plan), "--sim-mu", "0.5", "--sim-mass", "0.12", "--push", "0,1,0@0.2", "--json"]
    assert main(argv) == 0
    world = json.loads((plan / "sim.json").read_text())["conditions"]
    assert world == {
        "sim_mu": 0.5,
        "sim_mass": 0.12,
        "plan_mu": 0.7,
        "plan_mass": 0.094,
        "push": {"force": [0.0, 1.0, 0.0], "time_s": 0.2, "duration_s": 0.2},
    }
