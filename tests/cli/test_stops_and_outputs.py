"""The command line stopped by SIGTERM, and its output folders: checked before any work,
written whole or not at all, and a sweep's folder judged only by the sweep holding its lock.
Real processes throughout; each test uses the cheapest command that reaches its path."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

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


def forked_workers(pid: int) -> list[int]:
    """`pid`'s live children that run its own command line: its forked pool workers (not a
    short-lived helper a library starts, e.g. `uname`)."""
    try:
        command = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return []
    workers = []
    for other in session_processes(pid):
        fields = _stat(other)
        try:
            same = fields and int(fields[1]) == pid and Path(f"/proc/{other}/cmdline").read_bytes() == command
        except OSError:
            same = False
        if same:
            workers.append(other)
    return workers


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
