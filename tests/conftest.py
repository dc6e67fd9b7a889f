"""Shared fixtures. `resumed_sweep`: one small real sweep, killed mid-way and rerun,
which the sweep tests (resume, seeds, Dask) and the report tests all read."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest


@pytest.fixture
def ax():
    """A matplotlib Axes (Agg backend) whose figure is closed after the test."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    yield ax
    plt.close(fig)


# 2 goals in [-0.3, 0.3] rad (seed 0), 2 transition segments, two methods, executed.
SMALL_SWEEP = [
    "--goals",
    "2",
    "--seed",
    "0",
    "--max-goal",
    "0.3",
    "--segments",
    "2",
    "--methods",
    "trajectotree",
    "cito-warm",
    "--simulate",
    "--no-progress",
]


def trial_files(out: Path) -> dict[str, dict[str, tuple[int, int, int]]]:
    """key -> file -> (inode, mtime ns, size) of every finished trial."""
    trials = out / "trials"
    return (
        {
            d.name: {f.name: (f.stat().st_ino, f.stat().st_mtime_ns, f.stat().st_size) for f in d.iterdir()}
            for d in sorted(trials.iterdir())
            if d.is_dir() and not d.name.startswith(".")
        }
        if trials.is_dir()
        else {}
    )


@pytest.fixture(scope="session")
def resumed_sweep(tmp_path_factory):
    """Runs the small sweep on one worker, kills its whole process group (SIGKILL) once
    the first trial is stored, then reruns the same command on two workers."""
    out = tmp_path_factory.mktemp("sweep") / "small"
    command = [sys.executable, "-m", "trajectotree.cli", "sweep", *SMALL_SWEEP, "--out", str(out)]
    first = subprocess.Popen(
        command + ["--workers", "1"],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    while not trial_files(out):
        if first.poll() is not None:
            pytest.fail(f"the sweep ended (rc {first.returncode}) before it could be killed: {first.stderr.read()}")
        if time.monotonic() > deadline:
            os.killpg(first.pid, signal.SIGKILL)
            pytest.fail("no trial finished within 300 s")
        time.sleep(0.05)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    first.stderr.close()
    before = trial_files(out)
    rerun = subprocess.run(command + ["--workers", "2"], capture_output=True, text=True, timeout=900)
    return SimpleNamespace(out=out, before=before, rerun=rerun, command=command)
