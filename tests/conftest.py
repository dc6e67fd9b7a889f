"""Shared fixtures. `resumed_sweep`: one small real sweep, killed mid-way and rerun,
which the sweep tests (resume, seeds, Dask) and the report tests all read. `tiny_plan` and
`timed_out_sweep`: the cheapest plan folder and sweep folder, made once for the tests that start
from one; `space_plan`: the plan in space the simulate, replan and watch tests start from. Each of these once for the
whole run, under pytest-xdist too (_built_once). `shared_computations`: each scene's initial-grasp table and reach
report, once per session; `quarter_turn`: the contact plans in space of a quarter turn, once per process.
Test modules import the argument lists from here as `from conftest import ...` (tests/ is on
sys.path under `pytest` and `python -m pytest` alike; the package `tests` is not)."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

# Pure computations the tests share across the session. Every command and search ranks the candidate
# initial grasps of its scene (trajectotree.search.initial_grasp, ~0.2 s for the box's 2583), most of them of
# the default box: ~100 times in the quick suite; every `trajectotree scene` computes its report of the
# object's reach (cli.scene_cmd.object_reach: the table, the payload LP over every grasp, the workspace over
# 961 translations x 36 turns: ~1 s). Each is a function of the scene's config and the search settings alone:
# the table of the key trajectotree.search.initial_grasp.GraspTables shares it by across goals, the report of
# both configs whole. The tests share them likewise: each distinct one is still computed by the real code,
# once, and every caller still runs; the values are frozen (the report's arrays only read), so no test can
# change another's. A test of the ranking itself is marked fresh and computes its own;
# TRAJECTOTREE_TEST_FRESH=1 makes every test do so.
FRESH = bool(os.environ.get("TRAJECTOTREE_TEST_FRESH"))
_shared = {"fresh": FRESH, "values": {}}


def _share(module, name: str, key):
    """module.name, its values shared by key(*args) (None or an unhashable key: not shared)."""
    compute = getattr(module, name)

    def shared(*args, **kwargs):
        if kwargs:  # the callers pass positional arguments; anything else is not shared
            return compute(*args, **kwargs)
        k = key(*args)
        try:
            value = None if _shared["fresh"] or k is None else _shared["values"].get((name, k))
        except TypeError:
            k = None
        if value is None:
            value = compute(*args)
            if not _shared["fresh"] and k is not None:
                _shared["values"][name, k] = value
        return value

    setattr(module, name, shared)
    return lambda: setattr(module, name, compute)


@pytest.fixture(scope="session", autouse=True)
def shared_computations():
    from trajectotree.cli import scene_cmd
    from trajectotree.search import initial_grasp

    undo = [
        _share(
            initial_grasp,
            "_build",
            lambda scene, search, reach: (
                scene.config,
                search.friction_safety,
                search.initial_grid_step,
                search.nominal_joint2,
                search.finger_clearance,
            ),
        ),
        _share(scene_cmd, "object_reach", lambda scene, search: (scene.config, search)),
    ]
    yield _shared["values"]
    for step in undo:
        step()


# The quarter turn about x that seven modules search on fingerpro4 (tests/search, figures, cito), most of them with the
# default search settings or without the stance margin: 2-3 s a search.
QUARTER_ABOUT_X = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="session")
def quarter_turn():
    """search -> the contact plan find_space_contact_plan finds for QUARTER_ABOUT_X on fingerpro4 (Config()'s scene)
    with that SearchConfig at its mu_plan: each settings' plan searched once per process (shared as
    shared_computations shares its values: only read; a fresh test searches its own)."""
    from trajectotree.config import Config, mu_plan
    from trajectotree.scene.spatial import build_space_scene
    from trajectotree.search.space_tree import find_space_contact_plan

    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)

    def plan_of(search):
        key = ("quarter_turn", search)
        plan = None if _shared["fresh"] else _shared["values"].get(key)
        if plan is None:
            plan = find_space_contact_plan(scene, QUARTER_ABOUT_X, search, mu_plan(config.scene, search))
            if not _shared["fresh"]:
                _shared["values"][key] = plan
        return plan

    return plan_of


@pytest.fixture(autouse=True)
def _fresh(request):
    """A test marked fresh computes every shared value it asks for itself."""
    if request.node.get_closest_marker("fresh") is None:
        yield
        return
    _shared["fresh"] = True
    yield
    _shared["fresh"] = FRESH


# The cheapest plan: one transition segment (13 knots, 1.2 s), a small goal.
TINY_PLAN = ["--goal", "0.1", "--segments", "1"]
# A sweep whose trials hit the time limit before they plan (an interpreter with Drake takes
# longer than 0.1 s to start): every trial an error row, quickly.
TIMED_OUT_SWEEP = [
    *("--goals", "2", "--seed", "0", "--max-goal", "0.3", "--segments", "1", "--methods", "trajectotree"),
    *("--time-limit", "0.1", "--workers", "2", "--no-progress"),
]


@pytest.fixture(scope="session")
def tiny_plan(tmp_path_factory, worker_id) -> Path:
    """`trajectotree plan TINY_PLAN`'s folder (plan.json, plan.npz), once for the whole run (_written_once, in eight
    modules): copy it before changing it."""
    return _written_once(tmp_path_factory, worker_id, "tiny_plan", ["plan", *TINY_PLAN], "plan")


@pytest.fixture(scope="session")
def _timed_out_sweep(tmp_path_factory, worker_id) -> Path:
    return _written_once(tmp_path_factory, worker_id, "timed_out_sweep", ["sweep", *TIMED_OUT_SWEEP], "sweep")


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


def _run_resumed_sweep(out: Path) -> SimpleNamespace:
    """Runs the small sweep on one worker, kills its whole process group (SIGKILL) once
    the first trial is stored, then reruns the same command on two workers."""
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


def _built_once(tmp_path_factory, worker_id, name: str, build) -> dict:
    """build(folder) -> a JSON-able dict, run once for the whole run: under pytest-xdist the first process that asks
    builds it in the run's shared temporary folder `name`, the others wait for it and read what it returned."""
    base = tmp_path_factory.getbasetemp()
    folder = (base if worker_id == "master" else base.parent) / name
    done = folder / "done.json"
    try:
        folder.mkdir()  # atomic: the process that makes the folder builds it
    except FileExistsError:
        deadline = time.monotonic() + 1200
        while not done.exists():
            assert time.monotonic() < deadline, f"{done} was not written within 1200 s"
            time.sleep(0.1)
    else:
        try:
            saved = build(folder)
        except BaseException as error:  # the waiting processes fail at once instead of at their deadline
            saved = {"error": repr(error)}
            raise
        finally:
            (folder / "done.tmp").write_text(json.dumps(saved))
            (folder / "done.tmp").replace(done)
    saved = json.loads(done.read_text())
    if "error" in saved:
        pytest.fail(f"{name} failed in the process that built it: {saved['error']}")
    return saved


def _written_once(tmp_path_factory, worker_id, name: str, argv: list[str], out: str) -> Path:
    """FOLDER/out, which `trajectotree ARGV --out FOLDER/out` writes (the CLI's main, its exit code 0), once for the
    whole run (_built_once under `name`)."""

    def build(folder: Path) -> dict:
        from trajectotree.cli import main

        return {"out": str(folder / out), "code": main([*argv, "--out", str(folder / out)])}

    saved = _built_once(tmp_path_factory, worker_id, name, build)
    assert saved["code"] == 0, f"trajectotree {' '.join(argv)} exited {saved['code']}"
    return Path(saved["out"])


def _build_resumed_sweep(folder: Path) -> dict:
    sweep = _run_resumed_sweep(folder / "small")
    rerun = {k: getattr(sweep.rerun, k) for k in ("returncode", "stdout", "stderr")}
    return {"out": str(sweep.out), "before": sweep.before, "rerun": rerun, "command": sweep.command}


@pytest.fixture(scope="session")
def resumed_sweep(tmp_path_factory, worker_id):
    """The small sweep killed mid-way and rerun (_run_resumed_sweep), once for the whole run (_built_once: 15 s of
    a core each before; the tests only read it, copying it to change it)."""
    saved = _built_once(tmp_path_factory, worker_id, "resumed_sweep", _build_resumed_sweep)
    before = {key: {name: tuple(stat) for name, stat in files.items()} for key, files in saved["before"].items()}
    return SimpleNamespace(
        out=Path(saved["out"]), before=before, rerun=SimpleNamespace(**saved["rerun"]), command=saved["command"]
    )


# The plan in space that the simulate, closed-loop, replan, watch and joint-formulation tests start from: a 34 deg
# turn about x (2 segments), as `trajectotree plan` writes it.
SPACE_PLAN = ["plan", "--hand", "fingerpro4", "--goal-rpy", "0.6", "0", "0", "--segment-workers", "1"]


@pytest.fixture(scope="session")
def space_plan(tmp_path_factory, worker_id) -> Path:
    """`trajectotree plan SPACE_PLAN`'s folder (plan.json, plan.npz), once for the whole run (_written_once: 3-6 s of
    a core each before, in five modules): read only, copy it before changing it."""
    return _written_once(tmp_path_factory, worker_id, "space_plan", SPACE_PLAN, "plan")


def jacobian_against_differences(constraint, Z: np.ndarray):
    """(J, numeric, pattern) of a segment constraint (values(Z), jacobian(Z), sparsity()) at Z: its
    analytic Jacobian, central differences of its values (step 1e-6) and its declared sparsity as a
    mask; asserts the two Jacobians agree to 1e-6 relative to the largest entry."""
    _, J = constraint.jacobian(Z)
    step = 1e-6
    numeric = np.empty_like(J)
    for j in range(Z.size):
        d = np.zeros(Z.size)
        d[j] = step
        d = d.reshape(Z.shape)
        numeric[:, j] = (constraint.values(Z + d) - constraint.values(Z - d)) / (2 * step)
    assert np.abs(J - numeric).max() < 1e-6 * max(1.0, np.abs(J).max())
    pattern = np.zeros(J.shape, dtype=bool)
    pattern[tuple(np.array(constraint.sparsity()).T)] = True
    return J, numeric, pattern


def holding_torque(scene, pose, p_BC, n_B, q, fingers, mu) -> float:
    """The least largest joint torque (N m) with which the fingertips of `fingers` (p_BC, n_B and q: their rows,
    one per finger, B's contact points and normals and the joints) hold the cube at `pose` against gravity within
    friction `mu`: the search's holding LP built here from its parts."""
    from trajectotree.scene.statics import edge_wrenches_W
    from trajectotree.search.space_tree import PYRAMID_EDGES as edges
    from trajectotree.search.spatial_reach import box_transform
    from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

    R = box_transform(pose).rotation().matrix()
    p, n = p_BC @ R.T, n_B @ R.T
    J = np.array([scene.fingers[i].jacobian(q_i, -scene.tip_radius * n_i) for i, q_i, n_i in zip(fingers, q, n)])
    w_hold = np.r_[0, 0, scene.object.mass * scene.gravity, 0, 0, 0]
    all_q = np.zeros((scene.num_fingers, 3))
    all_q[list(fingers)] = q
    torque, _ = SpatialHoldingLp(len(fingers), edges, 3).solve(
        edge_wrenches_W(p, n, mu, edges),
        spatial_torque_rows(J, n, mu, edges),
        scene.gravity_torques(all_q)[list(fingers)],
        w_hold,
    )
    return torque
