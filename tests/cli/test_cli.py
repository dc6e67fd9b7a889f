"""A newcomer's first hour, through the command line: output paths, stale
files, unconverged plans, and the sweep's faults (corrupt trials, time limits, locks,
scratch files). Each test uses the cheapest command that reaches the path it checks."""

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import TIMED_OUT_SWEEP, TINY_PLAN

from trajectotree.cli import main
from trajectotree.experiments.sweep_store import CORRUPT_DIR, LOCK_FILE, TRIALS_DIR, read_rows


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ---- every output path is checked before any work starts ----------------------------


def output_path_cases(tmp: Path) -> list[tuple[list[str], str]]:
    """(arguments, expected message) of output paths no command can write."""
    a_file, a_folder = tmp / "a_file.png", tmp / "a_folder.png"
    a_file.write_text("keep me")
    a_folder.mkdir()
    missing = tmp / "missing" / "x.png"
    return [
        (["plan", *TINY_PLAN, "--out", str(a_file)], f"--out {str(a_file)!r} is an existing file"),
        (["plan", *TINY_PLAN, "--out", str(a_file / "sub")], f"{str(a_file)!r} is a file, not a folder"),
        (["plan", *TINY_PLAN, "--out", str(tmp / "p"), "--html", str(tmp / "p.txt")], "must end in .html"),
        (["demo", "--out", str(a_file)], f"--out {str(a_file)!r} is an existing file"),
        (["sweep", "--goals", "1", "--out", str(a_file)], f"--out {str(a_file)!r} is an existing file"),
        (["report", str(tmp), "--out", str(a_file)], f"--out {str(a_file)!r} is an existing file"),
        (["scene", "--figure", str(tmp / "x.txt")], "must end in .png or .pdf or .svg"),
        (["scene", "--figure", str(missing)], f"the folder {str(missing.parent)!r} does not exist"),
        (["search", "--goal", "0.1", "--figure", str(a_folder)], f"--figure {str(a_folder)!r} is a folder"),
        (["simulate", str(tmp), "--forces", str(missing)], f"the folder {str(missing.parent)!r} does not exist"),
        (["simulate", str(tmp), "--gif", str(tmp / "run.png")], "must end in .gif"),
        (["simulate", str(tmp), "--html", str(a_folder)], "must end in .html"),
    ]


def test_bad_output_paths_exit_2_naming_the_path_and_write_nothing(tmp_path, capsys):
    for args, message in output_path_cases(tmp_path):
        before = listing(tmp_path)
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert message in err, (args, err)
        assert "Traceback" not in err
        assert listing(tmp_path) == before, args  # nothing written, nothing removed
        assert (tmp_path / "a_file.png").read_text() == "keep me"


def test_report_into_a_sweep_whose_report_folder_is_a_file(timed_out_sweep, capsys):
    sweep = timed_out_sweep
    (sweep / "report").write_text("not a folder")
    assert main(["report", str(sweep)]) == 2
    assert f"{str(sweep / 'report')!r} is an existing file" in capsys.readouterr().err


# ---- a new plan in a used folder; simulating an unconverged plan -----------


def test_plan_into_a_used_folder_removes_the_older_simulation(tmp_path, capsys):
    out = tmp_path / "plan"
    out.mkdir()
    for name in ("sim.json", "sim.npz"):  # an older plan's run
        (out / name).write_text("{}")
    (out / "notes.txt").write_text("mine")
    assert main(["plan", *TINY_PLAN, "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert f"removed sim.json, sim.npz from {out}" in captured.err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "plan.json", "plan.npz"]


def test_demo_into_a_used_folder_leaves_none_of_the_older_run(tmp_path, capsys):
    config = tmp_path / "no_search.yaml"
    config.write_text("search:\n  max_expansions: 1\n")  # the search gives up: no trajectory, no run
    out = tmp_path / "demo"
    out.mkdir()
    older = ("sim.json", "sim.npz", "keyframes.png", "playback.html", "forces.png", "summary.json")
    for name in older:
        (out / name).write_text("older run")
    assert main(["demo", "--out", str(out), "--config", str(config), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["plan"]["success"] is False and summary["simulation"] is None
    assert sorted(p.name for p in out.iterdir()) == ["plan.json", "plan.npz", "summary.json"]
    assert json.loads((out / "summary.json").read_text()) == summary


def test_simulating_an_unconverged_plan_warns_and_records_it(tmp_path, capsys):
    config = tmp_path / "three_iterations.yaml"
    config.write_text("cito:\n  max_iter: 3\n  formulation: joint\n")  # one program: IPOPT's status as is
    out = tmp_path / "plan"
    assert main(["plan", *TINY_PLAN, "--config", str(config), "--out", str(out)]) == 0
    plan_json = json.loads((out / "plan.json").read_text())
    assert plan_json["success"] is False and plan_json["status"] == "Max iteration exceeded"
    capsys.readouterr()
    assert main(["simulate", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    assert "warning: the plan in" in captured.err and "did not converge" in captured.err
    assert "'Max iteration exceeded'" in captured.err
    sim_json = json.loads((out / "sim.json").read_text())
    assert sim_json["plan_success"] is False and json.loads(captured.out) == sim_json


# ---- the sweep's faults ---------------------------------------------------------------


def test_corrupt_trial_is_named_moved_aside_and_recomputed(timed_out_sweep, capsys):
    sweep = timed_out_sweep
    corrupt = sweep / TRIALS_DIR / "0001_trajectotree" / "trial.json"
    corrupt.write_text('{"key": "0001_traj')  # torn by a full disk, say
    assert main(["report", str(sweep)]) == 2  # the report names the file
    err = capsys.readouterr().err
    assert f"{str(corrupt)!r} is unreadable (JSONDecodeError" in err and "Traceback" not in err
    assert main(["sweep", "--out", str(sweep), *TIMED_OUT_SWEEP]) == 0
    captured = capsys.readouterr()
    assert f"{str(corrupt)!r} was unreadable" in captured.err and "it is recomputed" in captured.err
    assert "1 now, 1 before" in captured.out
    moved = list((sweep / CORRUPT_DIR).iterdir())
    assert len(moved) == 1 and moved[0].name.startswith("0001_trajectotree-")
    assert (moved[0] / "trial.json").read_text() == '{"key": "0001_traj'
    assert [r["key"] for r in read_rows(sweep)] == ["0000_trajectotree", "0001_trajectotree"]


def test_report_names_an_unreadable_manifest_or_sim_npz(timed_out_sweep, capsys):
    sweep = timed_out_sweep
    trial = sweep / TRIALS_DIR / "0000_trajectotree"
    row = json.loads((trial / "trial.json").read_text())
    (trial / "trial.json").write_text(json.dumps(dict(row, simulated=True)))  # as if executed ...
    (trial / "sim.npz").write_bytes(b"PK\x03\x04 torn")  # ... and its file torn
    capsys.readouterr()
    assert main(["report", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert f"{str(trial / 'sim.npz')!r} is unreadable" in err and "Traceback" not in err
    (sweep / "manifest.json").write_text("{")
    assert main(["report", str(sweep)]) == 2
    assert f"{str(sweep / 'manifest.json')!r} is unreadable (JSONDecodeError" in capsys.readouterr().err


def test_retry_errors_may_raise_the_time_limit(timed_out_sweep, capsys):
    sweep = timed_out_sweep
    assert [r["error"] for r in read_rows(sweep)] == ["timeout: exceeded the trial time limit of 0.1 s"] * 2
    raised = TIMED_OUT_SWEEP + ["--time-limit", "0.2"]  # the last one counts
    assert main(["sweep", "--out", str(sweep), *raised]) == 0  # not --retry-errors: both skipped
    assert "0 now, 2 before" in capsys.readouterr().out
    assert main(["sweep", "--out", str(sweep), *raised, "--retry-errors"]) == 0
    assert "2 now, 0 before" in capsys.readouterr().out
    assert [r["error"] for r in read_rows(sweep)] == ["timeout: exceeded the trial time limit of 0.2 s"] * 2
    assert json.loads((sweep / "manifest.json").read_text())["time_limit_s"] == 0.2


HOLD_LOCK = """
import sys, time
from pathlib import Path
from trajectotree.experiments.sweep_store import sweep_lock
with sweep_lock(Path(sys.argv[1])):
    print("locked", flush=True)
    time.sleep(600)
"""


def test_second_sweep_on_one_folder_is_refused_and_a_dead_holders_lock_taken_over(tmp_path, capsys):
    sweep = tmp_path / "sweep"
    holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(sweep)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "locked\n"
        assert main(["sweep", "--out", str(sweep), *TIMED_OUT_SWEEP]) == 2
        err = capsys.readouterr().err
        assert f"is in use by another sweep (process pid {holder.pid} on" in err
        assert listing(sweep) == [LOCK_FILE]  # nothing computed, nothing written
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    assert f"pid {holder.pid} " in (sweep / LOCK_FILE).read_text()  # the dead holder's stale lock
    assert main(["sweep", "--out", str(sweep), *TIMED_OUT_SWEEP]) == 0
    captured = capsys.readouterr()
    assert f"taking over the stale lock of process pid {holder.pid}" in captured.err
    assert "2 now, 0 before" in captured.out
    assert (sweep / LOCK_FILE).read_text() == ""  # released


@pytest.mark.slow
def test_killed_sweep_leaves_no_scratch_in_the_system_temp_folder(tmp_path):
    """Kills a sweep and its trial (SIGKILL to the process group) while the trial's IPOPT
    runs; the system temp folder (TMPDIR) stays empty and the rerun removes the scratch."""
    system_tmp, sweep = tmp_path / "tmp", tmp_path / "sweep"
    system_tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(system_tmp)}
    command = [
        sys.executable,
        "-m",
        "trajectotree.cli",
        "sweep",
        "--out",
        str(sweep),
        "--goals",
        "1",
        "--seed",
        "0",
        "--max-goal",
        "0.3",
        "--segments",
        "1",
        "--methods",
        "cito",
        "--workers",
        "1",
        "--no-progress",
    ]
    first = subprocess.Popen(
        command, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.monotonic() + 120
    try:
        while not list((sweep / TRIALS_DIR).glob(".tmp-scratch-*/tmp/*")):  # IPOPT's log: solving
            assert first.poll() is None and time.monotonic() < deadline, "the trial never reached IPOPT"
            time.sleep(0.05)
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    assert list(system_tmp.iterdir()) == []
    assert list((sweep / TRIALS_DIR).glob(".tmp-scratch-*"))  # left by the killed trial
    rerun = subprocess.run(command + ["--time-limit", "0.3"], env=env, capture_output=True, text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    assert not list((sweep / TRIALS_DIR).glob(".tmp-*")) and list(system_tmp.iterdir()) == []


# ---- messages state the real limit in the user's terms -------------------------------------


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["search", "--goal", "62.8319"],
            "--goal = 62.8319 is out of range; valid range: [-20 pi, 20 pi] rad, 20 pi = 62.83185307",
        ),
        (
            ["scene", "--box-size", "0", "0.1"],
            "--box-size W (scene.box_width) = 0.0 is out of range; valid range: (0, 0.3]",
        ),
        (
            ["scene", "--box-size", "0.2", "0.5"],
            "--box-size H (scene.box_height) = 0.5 is out of range; valid range: (0, 0.3]",
        ),
        (
            ["scene", "--box-size", "0.01", "0.01"],
            "--box-size W H (scene.box_width x scene.box_height) = "
            "0.01 x 0.01 m is too small: contacts keep "
            "scene.corner_margin = 0.015 m from each corner, so each side must "
            "be longer than 0.03 m; valid range of each side: (0.03, 0.3] m",
        ),
        (["scene", "--mu", "0"], "--mu (scene.mu) = 0.0 is out of range; valid range: (0, 5]"),
        (["scene", "--config", "."], "config file '.' is a folder; give a YAML file"),
    ],
)
def test_messages_name_the_option_and_its_real_limit(args, message, capsys):
    assert main(args) == 2
    assert capsys.readouterr().err == f"trajectotree {args[0]}: error: {message}\n"


def test_a_config_file_value_keeps_its_field_name(tmp_path, capsys):
    config = tmp_path / "box.yaml"
    config.write_text("scene:\n  box_width: 0.5\n")
    assert main(["scene", "--config", str(config)]) == 2
    assert "scene.box_width = 0.5 is out of range; valid range: (0, 0.3]" in capsys.readouterr().err


# ---- IPOPT's progress on a terminal, and nothing the user did not ask for --------------------


def run_on_a_terminal(args: list[str]) -> tuple[int, str, str]:
    """Runs the CLI with stderr on a pseudo-terminal: (exit code, stdout, what the terminal showed)."""
    import pty

    master, slave = pty.openpty()
    child = subprocess.Popen(
        [sys.executable, "-m", "trajectotree.cli", *args],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=slave,
    )
    os.close(slave)
    shown = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        shown += chunk
    os.close(master)
    out = child.stdout.read().decode()
    child.stdout.close()
    return child.wait(), out, shown.decode(errors="replace")


@pytest.mark.slow
def test_ipopt_progress_shows_on_a_terminal_and_not_with_json(tmp_path):
    rc, out, shown = run_on_a_terminal(["plan", *TINY_PLAN, "--out", str(tmp_path / "a")])
    assert rc == 0 and "wrote" in out
    assert re.search(r"IPOPT iteration \d+: objective [-+0-9.e]+, constraint violation [0-9.e+-]+", shown), shown
    assert shown.endswith("\r\033[K")  # the progress line is cleared before the summary
    rc, out, shown = run_on_a_terminal(["plan", *TINY_PLAN, "--out", str(tmp_path / "b"), "--json"])
    assert rc == 0 and json.loads(out)["method"] == "trajectotree"
    assert "IPOPT" not in shown


# Recording a playback prints no Meshcat server line: checked on the plan --html of
# test_stops_and_outputs.py::test_plan_html_may_go_into_the_out_folder_it_creates_and_prints_no_meshcat_line.


# ---- small things -----------------------------------------------------------------------------


def test_help_cites_no_design_document_and_defines_segments_once(capsys):
    from trajectotree.cli import COMMANDS
    from trajectotree.cli.common import SEGMENTS_HELP

    for command in COMMANDS:
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
        assert "DESIGN" not in text, command
        if "--segments" in text:
            assert f"--segments S {SEGMENTS_HELP}" in text, command
    package = Path(__file__).resolve().parents[2] / "trajectotree"
    assert [p.name for p in package.rglob("*.py") if "DESIGN.md" in p.read_text()] == []


def test_default_outputs_are_ignored_by_git():
    root = Path(__file__).resolve().parents[2]
    ignored = subprocess.run(
        [
            "git",
            "check-ignore",
            "demo/plan.json",
            "plan_trajectotree_+0.300/plan.json",
            "sweep/manifest.json",
            "paper-sweep/manifest.json",
        ],
        cwd=root,
        capture_output=True,
        text=True,
    )
    assert ignored.stdout.split() == [
        "demo/plan.json",
        "plan_trajectotree_+0.300/plan.json",
        "sweep/manifest.json",
        "paper-sweep/manifest.json",
    ]
