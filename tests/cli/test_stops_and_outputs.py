"""The command line stopped by SIGTERM, and its output folders: checked before any work,
written whole or not at all, and a sweep's folder judged only by the sweep holding its lock.
Real processes throughout; each test uses the cheapest command that reaches its path."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import TIMED_OUT_SWEEP, TINY_PLAN

from trajectotree.cli import main
from trajectotree.experiments.sweep_store import CORRUPT_DIR, TRIALS_DIR

# Two segments whose IPOPT stalls (the paper's cost alone, without the acceleration term, runs
# to thousands of iterations: ~30 s per segment), so two segment workers are busy for long.
STALLING_CITO = "cito:\n  weight_acceleration: 0.0\n  max_iter: 100000\n"
STALLING_PLAN = ["--goal", "0.3", "--segments", "2"]


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "trajectotree.cli", *args]


def _stat(pid: int | str) -> list[str] | None:
    """/proc/PID/stat's fields after "pid (comm)": state, ppid, pgrp, session, ...; None when gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2 :].split()


def session_processes(sid: int) -> list[int]:
    """The pids of the live processes (zombies excluded) in session `sid`: an orphaned
    worker keeps its session when it is reparented, so none is missed."""
    pids = []
    for entry in Path("/proc").iterdir():
        fields = _stat(entry.name) if entry.name.isdigit() else None
        if fields and int(fields[3]) == sid and fields[0] != "Z":
            pids.append(int(entry.name))
    return pids


def cmdline(pid: int) -> bytes:
    """`pid`'s command line as /proc has it (b"" when gone)."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def children(pid: int) -> list[int]:
    """`pid`'s live children."""
    return [p for p in session_processes(pid) if (fields := _stat(p)) and int(fields[1]) == pid]


def forked_workers(pid: int) -> list[int]:
    """`pid`'s live children that run its own command line: its forked pool workers (not a
    short-lived helper a library starts, e.g. `uname`)."""
    command = cmdline(pid)
    return [p for p in children(pid) if command and cmdline(p) == command]


@pytest.mark.slow  # a command's process and its two segment workers, seconds each
@pytest.mark.parametrize("command", ["plan", "demo"])
def test_sigterm_stops_the_segment_workers_exits_143_and_writes_nothing(command, tmp_path):
    config, out, log = tmp_path / "stalling.yaml", tmp_path / "out", tmp_path / "stderr.txt"
    config.write_text(STALLING_CITO)
    with open(log, "w") as stderr:  # a file, not a pipe: a surviving worker would hold a pipe open
        child = subprocess.Popen(
            cli(command, *STALLING_PLAN, "--config", str(config), "--out", str(out)),
            start_new_session=True,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
        )
    try:
        deadline = time.monotonic() + 120
        while len(workers := forked_workers(child.pid)) < 2:  # its two segment workers, solving
            assert child.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "the segment workers never started"
            time.sleep(0.05)
        child.send_signal(signal.SIGTERM)  # to the command alone, as `kill PID` does
        assert (child.wait(timeout=60), log.read_text()) == (143, f"trajectotree {command}: terminated (SIGTERM)\n")
        assert session_processes(child.pid) == [], f"left running, of the workers {workers}"
        assert not out.exists()  # stopped while planning: nothing written
    finally:
        try:
            os.killpg(child.pid, signal.SIGKILL)  # whatever the fix failed to stop
        except ProcessLookupError:
            pass
        child.wait()


# ---- output folders: checked before any work, by trying --------------------------------------------


def listing(folder: Path) -> dict[str, bytes | None]:
    """Every path under `folder` with its contents (None: a folder), hidden ones too."""
    return {str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes() for p in sorted(folder.rglob("*"))}


@pytest.fixture
def read_only():
    """make(folder): `folder` refuses new files from now on (undone after the test). Tests run
    as root here, and root ignores permission bits (chmod 555 would prove nothing), so as root
    the folder is made immutable (chattr +i) or bind-mounted read-only; either fails for root
    too. A folder that still takes a file afterwards skips the test rather than pass it."""
    undo = []

    def make(folder: Path) -> None:
        if os.geteuid() != 0:
            folder.chmod(0o555)
            undo.append(lambda: folder.chmod(0o755))
        elif subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0:
            undo.append(lambda: subprocess.run(["chattr", "-i", str(folder)], check=True))
        elif (
            subprocess.run(["mount", "--bind", "-o", "ro", str(folder), str(folder)], capture_output=True).returncode
            == 0
        ):
            undo.append(lambda: subprocess.run(["umount", str(folder)], check=True))
        try:
            (folder / "probe").touch()
        except OSError:
            return  # read-only, for this process too
        (folder / "probe").unlink()
        pytest.skip(f"cannot make {folder} read-only for this process (not root with chattr or mount)")

    yield make
    for step in reversed(undo):
        step()


def test_simulate_into_a_plan_folder_it_cannot_write_exits_2_before_simulating(tiny_plan, tmp_path, read_only, capsys):
    plan = tmp_path / "plan"
    shutil.copytree(tiny_plan, plan)
    (plan / "sim.npz").mkdir()  # where simulate saves its arrays: no user can write there
    before = listing(tmp_path)
    capsys.readouterr()
    assert main(["simulate", str(plan)]) == 2
    err = capsys.readouterr().err
    assert f"PLAN_DIR {str(plan)!r} cannot be written: {str(plan / 'sim.npz')!r} is a folder" in err, err
    (plan / "sim.npz").rmdir()
    read_only(plan)
    before = listing(tmp_path)
    assert main(["simulate", str(plan)]) == 2
    err = capsys.readouterr().err
    assert f"PLAN_DIR {str(plan)!r} cannot be written: no file can be created in {str(plan)!r}" in err, err
    assert "Traceback" not in err and listing(tmp_path) == before


def test_report_of_a_sweep_it_cannot_write_into_exits_2_naming_the_folder(timed_out_sweep, tmp_path, read_only, capsys):
    sweep = timed_out_sweep
    read_only(sweep)  # SWEEP_DIR/report, the default, cannot be created
    before = listing(tmp_path)
    capsys.readouterr()
    assert main(["report", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert (
        f"the report folder (default: SWEEP_DIR/report) {str(sweep / 'report')!r} cannot be written: "
        f"no file can be created in {str(sweep)!r}"
    ) in err, err
    assert "Traceback" not in err and listing(tmp_path) == before


def test_plan_html_may_go_into_the_out_folder_it_creates_and_prints_no_meshcat_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["plan", *TINY_PLAN, "--out", str(out), "--html", str(tmp_path / "out" / "sub" / "plan.html")]) == 2
    assert f"the folder {str(out / 'sub')!r} does not exist" in capsys.readouterr().err  # only --out itself is made
    assert not out.exists()
    assert main(["plan", *TINY_PLAN, "--out", str(out), "--html", str(out / "plan.html")]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["plan.html", "plan.json", "plan.npz"]
    assert "<html" in (out / "plan.html").read_text()[:2000].lower()
    # recording the playback prints no Meshcat server line (nor, off a terminal, IPOPT's progress)
    captured = capsys.readouterr()
    assert "listening" not in captured.out + captured.err and "IPOPT iteration" not in captured.err


# ---- a report is written whole or not at all; the sweep recomputes what it cannot read ---------------


def test_report_with_a_torn_sim_npz_writes_nothing_and_the_sweep_recomputes_that_trial(
    timed_out_sweep, tmp_path, capsys
):
    sweep = timed_out_sweep
    assert main(["report", str(sweep), "--out", str(tmp_path / "older")]) == 0  # an earlier report, kept as is
    trial = sweep / TRIALS_DIR / "0001_trajectotree"
    row = json.loads((trial / "trial.json").read_text())
    (trial / "trial.json").write_text(json.dumps(dict(row, simulated=True)))  # as if executed ...
    (trial / "sim.npz").write_bytes(b"PK\x03\x04 torn")  # ... and its arrays torn by a full disk
    before = listing(tmp_path)
    capsys.readouterr()
    for out in ([], ["--out", str(tmp_path / "older")]):  # a new report folder, and one with a report in it
        assert main(["report", str(sweep), *out]) == 2
        err = capsys.readouterr().err
        assert f"{str(trial / 'sim.npz')!r} is unreadable (BadZipFile" in err and "rerun the sweep" in err, err
        assert listing(tmp_path) == before  # no report folder, no half report, no staging folder
    assert main(["sweep", "--out", str(sweep), *TIMED_OUT_SWEEP]) == 0
    captured = capsys.readouterr()
    assert f"{str(trial / 'sim.npz')!r} was unreadable (BadZipFile" in captured.err, captured.err
    assert "it is recomputed" in captured.err and "1 now, 1 before" in captured.out
    assert [p.name for p in (sweep / CORRUPT_DIR).iterdir()][0].startswith("0001_trajectotree-")
    assert main(["report", str(sweep)]) == 0
    assert sorted(p.name for p in (sweep / "report").iterdir()) == [
        "fig2_time_cost.pdf",
        "fig2_time_cost.png",
        "summary.csv",
        "summary.md",
    ]


# ---- two sweeps on one folder: the lock decides, before the folder is judged ---------------------------

# A sweep that has taken the lock and made trials/, its manifest not yet written: what a second
# sweep started at the same instant may find.
STARTING_SWEEP = """
import sys, time
from pathlib import Path
from trajectotree.experiments.sweep_store import TRIALS_DIR, sweep_lock
out = Path(sys.argv[1])
with sweep_lock(out):
    (out / TRIALS_DIR).mkdir()
    print("started", flush=True)
    time.sleep(600)
"""


def test_a_sweep_meeting_another_one_starting_reports_its_lock(tmp_path, capsys):
    sweep = tmp_path / "sweep"
    holder = subprocess.Popen([sys.executable, "-c", STARTING_SWEEP, str(sweep)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "started\n"
        before = listing(sweep)
        assert main(["sweep", "--out", str(sweep), *TIMED_OUT_SWEEP]) == 2
        err = capsys.readouterr().err
        assert f"is in use by another sweep (process pid {holder.pid} on" in err, err
        assert listing(sweep) == before
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()


@pytest.mark.slow  # two sweep processes and their trials
def test_two_sweeps_started_together_one_runs_the_other_is_refused_by_the_lock(tmp_path):
    """Both started at once, the same arguments; trials that stall (killed by SIGTERM at the end)
    keep the first sweep holding the lock until the second has been refused."""
    config, sweep = tmp_path / "stalling.yaml", tmp_path / "sweep"
    config.write_text(STALLING_CITO)
    args = cli("sweep", "--out", str(sweep), "--config", str(config), *TIMED_OUT_SWEEP, "--time-limit", "300")
    logs = [tmp_path / "a.txt", tmp_path / "b.txt"]
    sweeps = []
    for log in logs:
        with open(log, "w") as stderr:
            sweeps.append(subprocess.Popen(args, start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr))
    try:
        deadline = time.monotonic() + 120
        while all(s.poll() is None for s in sweeps):
            assert time.monotonic() < deadline, "neither sweep ended"
            time.sleep(0.05)
        (refused, log), (running, _) = sorted(zip(sweeps, logs), key=lambda pair: pair[0].returncode is None)
        err = log.read_text()
        assert refused.returncode == 2 and "is in use by another sweep (process pid " in err, err
        assert "without manifest.json" not in err
        running.send_signal(signal.SIGTERM)  # stops its trials like Ctrl-C
        assert running.wait(timeout=60) == 143
        assert session_processes(running.pid) == []  # its trials stopped too
        assert (sweep / "manifest.json").is_file() and (sweep / ".lock").read_text() == ""
    finally:
        for s in sweeps:
            try:
                os.killpg(s.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            s.wait()


@pytest.mark.slow
def test_a_torn_execution_is_named_by_the_report_and_redone_by_the_sweep(resumed_sweep, tmp_path, capsys):
    from conftest import SMALL_SWEEP

    sweep = tmp_path / "sweep"
    shutil.copytree(resumed_sweep.out, sweep)
    args = ["sweep", *SMALL_SWEEP, "--out", str(sweep), "--controllers", "grasp"]  # copies the sweep's own runs
    assert main(args) == 0
    trial = sweep / TRIALS_DIR / "0000_trajectotree"
    torn = trial / "exec" / "grasp_nominal" / "sim.npz"
    torn.write_bytes(torn.read_bytes()[:1000])
    before = listing(tmp_path)
    capsys.readouterr()
    assert main(["report", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert f"{str(torn)!r} is unreadable (" in err and "rerun the sweep" in err, err
    assert listing(tmp_path) == before
    assert main(args) == 0
    assert torn.read_bytes() == (trial / "sim.npz").read_bytes()  # copied again from the trial's run
    assert main(["report", str(sweep)]) == 0
    assert (sweep / "report" / "executions.md").is_file()


@pytest.mark.slow
def test_sigterm_stops_a_sweeps_executions_without_running_the_queued_ones(resumed_sweep, tmp_path):
    from conftest import SMALL_SWEEP

    sweep, log = tmp_path / "sweep", tmp_path / "stderr.txt"
    shutil.copytree(resumed_sweep.out, sweep)
    args = cli("sweep", *SMALL_SWEEP, "--out", str(sweep), "--controllers", "paper", "--workers", "2")
    with open(log, "w") as stderr:
        child = subprocess.Popen(args, start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        deadline = time.monotonic() + 120
        while not any(b"multiprocessing" in cmdline(p) for p in children(child.pid)):  # spawned workers
            assert child.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "the execution workers never started"
            time.sleep(0.05)
        child.send_signal(signal.SIGTERM)  # while the workers still start: no execution has finished
        assert (child.wait(timeout=60), log.read_text()) == (143, "trajectotree sweep: terminated (SIGTERM)\n")
        deadline = time.monotonic() + 10  # multiprocessing's resource tracker ends once its pipe closes
        while session_processes(child.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session_processes(child.pid) == []
        assert list(sweep.glob("trials/*/exec/paper_nominal/sim.json")) == []  # the 4 queued ones never ran
    finally:
        try:
            os.killpg(child.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        child.wait()
