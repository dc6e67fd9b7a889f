"""Shared fixtures. `resumed_sweep`: one small real sweep, killed mid-way and rerun,
which the sweep tests (resume, seeds, Dask) and the report tests all read. `tiny_plan` and
`timed_out_sweep`: the cheapest plan folder and sweep folder, made once for the tests that start
from one. `shared_grasp_tables`: each scene's ranked initial-grasp table built once per session.
Test modules import the argument lists from here as `from conftest import ...` (tests/ is on
sys.path under `pytest` and `python -m pytest` alike; the package `tests` is not)."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

# Every command and search ranks the candidate initial grasps of its scene (trajectotree.search.initial_grasp,
# ~0.2 s for the box's 2583), most of them of the default box: ~100 times in the quick suite. The table is a
# pure function of the scene's config and three search settings, the key trajectotree.search.initial_grasp.GraspTables
# shares one table by across goals; the tests share it likewise, across the session: each distinct table is
# still built by the real code, once, and every caller (check_graspable, the search, payload, scene) still runs.
# The tables are frozen values, so no test can change another's. A test of the ranking itself is marked
# fresh_grasp_tables and builds its own; TRAJECTOTREE_TEST_FRESH_GRASP_TABLES=1 builds every table afresh.
FRESH_GRASP_TABLES = bool(os.environ.get("TRAJECTOTREE_TEST_FRESH_GRASP_TABLES"))
_grasp_tables = {"fresh": FRESH_GRASP_TABLES, "tables": {}}


@pytest.fixture(scope="session", autouse=True)
def shared_grasp_tables():
    from trajectotree.search import initial_grasp

    build = initial_grasp._build

    def shared_build(scene, search, reach):
        key = (scene.config, search.friction_safety, search.initial_grid_step, search.nominal_joint2)
        try:
            table = None if _grasp_tables["fresh"] else _grasp_tables["tables"].get(key)
        except TypeError:  # an unhashable config value: no sharing
            return build(scene, search, reach)
        if table is None:
            table = build(scene, search, reach)
            if not _grasp_tables["fresh"]:
                _grasp_tables["tables"][key] = table
        return table

    initial_grasp._build = shared_build
    yield _grasp_tables["tables"]
    initial_grasp._build = build


@pytest.fixture(autouse=True)
def _fresh_grasp_tables(request):
    """A test marked fresh_grasp_tables builds every table it asks for itself."""
    if request.node.get_closest_marker("fresh_grasp_tables") is None:
        yield
        return
    _grasp_tables["fresh"] = True
    yield
    _grasp_tables["fresh"] = FRESH_GRASP_TABLES


# The cheapest plan: one transition segment (13 knots, 1.2 s), a small goal.
TINY_PLAN = ["--goal", "0.1", "--segments", "1"]
# A sweep whose trials hit the time limit before they plan (an interpreter with Drake takes
# longer than 0.3 s to start): every trial an error row, quickly.
TIMED_OUT_SWEEP = [
    *("--goals", "2", "--seed", "0", "--max-goal", "0.3", "--segments", "1", "--methods", "trajectotree"),
    *("--time-limit", "0.3", "--workers", "2", "--no-progress"),
]


@pytest.fixture(scope="session")
def tiny_plan(tmp_path_factory) -> Path:
    """`trajectotree plan TINY_PLAN`'s folder (plan.json, plan.npz), shared: copy it before changing it."""
    from trajectotree.cli import main

    out = tmp_path_factory.mktemp("tiny_plan") / "plan"
    assert main(["plan", *TINY_PLAN, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="session")
def _timed_out_sweep(tmp_path_factory) -> Path:
    from trajectotree.cli import main

    out = tmp_path_factory.mktemp("timed_out_sweep") / "sweep"
    assert main(["sweep", "--out", str(out), *TIMED_OUT_SWEEP]) == 0
    return out


@pytest.fixture
def timed_out_sweep(_timed_out_sweep, tmp_path) -> Path:
    """tmp_path/sweep: a copy of the folder `trajectotree sweep --out SWEEP TIMED_OUT_SWEEP` left (its
    lock released, both trials error rows), for a test to change or to run the sweep on again."""
    sweep = tmp_path / "sweep"
    shutil.copytree(_timed_out_sweep, sweep)
    return sweep


@pytest.fixture
def ax():
    """A matplotlib Axes (Agg backend) whose figure is closed after the test."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    yield ax
    plt.close(fig)


# 2 goals in [-0.3, 0.3] rad (seed 0), 2 transition segments, two methods, executed; IPOPT stopped at 300
# iterations (small_sweep.yaml: goal 1's cito-warm plan runs to the limit unconverged, 1000 iterations by default).
SMALL_SWEEP = [
    "--config",
    str(Path(__file__).with_name("small_sweep.yaml")),
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
