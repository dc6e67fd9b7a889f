"""One trial of a sweep: plan one goal with one method, and optionally execute the plan.

Every trial runs in a child process of its own (`python -m trajectotree.experiments.trial SCRATCH`
with the task as JSON on stdin; it writes its files into SCRATCH/out and its temporary
files, e.g. IPOPT's log, into SCRATCH/tmp, its TMPDIR). A sweep puts SCRATCH inside its
directory (trials/.tmp-scratch-*), so a killed trial leaves nothing in the system's temp
folder and the next run of the sweep removes what it left. That gives the sweep a hard per-trial time limit
(a solver deep in C++ cannot be interrupted any other way), survives a crash inside
a solver, and works the same on a local machine and on a Dask worker: `execute_trial`
supervises the child and returns the trial's files as bytes, so the sweep's single
writer stores them and the cluster needs no shared filesystem. Drake objects are never
pickled: each child builds its own scene. The cost is one interpreter start per trial
(well under a second, against seconds to minutes of planning).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON

# Row fields, in the order of trials.jsonl and the CSV table.
PLAN_FIELDS = (
    "success",
    "converged",
    "status",
    "search_time_s",
    "build_time_s",
    "solve_time_s",
    "total_time_s",
    "cost",
    "iterations",
)
SIM_FIELDS = ("mae_x", "mae_y", "mae_theta", "final_error", "dropped", "drop_time_s", "error_at_drop", "sim_time_s")
ROW_FIELDS = (
    ("key", "goal_index", "goal", "method")
    + PLAN_FIELDS
    + ("switching_fingers", "simulated")
    + SIM_FIELDS
    + ("trial_wall_s", "error")
)
# A trial in space adds these (plan.json's check and final error; plan_arrays: whether plan.npz was written, which a
# plan whose search found no contact sequence has not; its contact plan's nodes whose stances hold at the search's
# stance margin, of its nodes: search.space_stance_margin).
SPACE_FIELDS = ("check_passed", "final_error_deg", "plan_arrays", "margin_stances", "stances")
# ... and with --simulate its open-loop run's (sim.json of execution.space_run; dropped, drop_time_s and sim_time_s
# are SIM_FIELDS): the final orientation error (rad) and position error (m), and the field's two success criteria.
SPACE_SIM_FIELDS = ("final_orientation_error_rad", "final_position_error_m", "within_15deg", "within_0p4rad")
ROW_FILE = "trial.json"
LOG_FILE = "log.txt"
STDERR_TAIL_CHARS = 4000
SCRATCH_PREFIX = ".tmp-scratch-"  # sweep.prepare_dir removes trials/.tmp-* leftovers


@dataclass(frozen=True)
class TrialTask:
    """What one trial does; plain data, so it pickles to any executor."""

    key: str  # "<goal index>_<method>", the trial's directory name
    goal_index: int  # index into the sweep's goals
    goal: float | list[float]  # rad, goal rotation; in space the goal quaternion [w, x, y, z]
    method: str  # "trajectotree" | "cito" | "cito-warm"
    simulate: bool  # execute the plan in simulation
    config: dict  # trajectotree.config.config_to_dict(Config)
    time_limit_s: float  # s, wall clock for plan + simulation; the child is killed beyond it
    space: dict | None = None  # a hand in space: its box (sweep.SpaceSweepObject.to_json); None: planar


@dataclass(frozen=True)
class TrialOutcome:
    row: dict  # one row of trials.jsonl (ROW_FIELDS)
    files: dict[str, bytes]  # file name -> contents, to be stored in the trial's directory


class TrialInterrupted(RuntimeError):
    """The child was stopped by the user (SIGINT/SIGTERM) or the sweep shut down: not a result."""


class TrialChildren:
    """The trial processes a sweep runs from this process (its threads start them), so that an
    interrupted sweep can stop the running ones and start no queued one (`stop`)."""

    def __init__(self):
        self._running: set[subprocess.Popen] = set()
        self._lock = threading.Lock()
        self._stopping = threading.Event()

    @property
    def stopping(self) -> bool:
        return self._stopping.is_set()

    def add(self, child: subprocess.Popen) -> None:
        with self._lock:
            self._running.add(child)

    def discard(self, child: subprocess.Popen) -> None:
        with self._lock:
            self._running.discard(child)

    def stop(self) -> None:
        """Kills every running trial; trials started after this raise TrialInterrupted."""
        self._stopping.set()
        with self._lock:
            for child in list(self._running):
                child.kill()


def empty_row(task: TrialTask) -> dict:
    row = dict.fromkeys(ROW_FIELDS + (() if task.space is None else SPACE_FIELDS + SPACE_SIM_FIELDS))
    row.update(key=task.key, goal_index=task.goal_index, goal=task.goal, method=task.method, simulated=False)
    return row


def row_from_files(task: TrialTask, out_dir: Path) -> dict:
    """The trial's row, read back from the files the planner and simulator wrote
    (their documented JSON keys: plan.json and sim.json in the README)."""
    row = empty_row(task)
    plan_json = json.loads((out_dir / PLAN_JSON).read_text())
    row.update({k: plan_json.get(k) for k in PLAN_FIELDS})
    if row["converged"] is None:  # plan.json from before the physics check: success meant converged
        row["converged"] = row["success"]
    row["switching_fingers"] = [n.get("switching_finger") for n in plan_json.get("contact_sequence") or ()]
    sim_path = out_dir / SIM_JSON
    if sim_path.is_file():
        sim_json = json.loads(sim_path.read_text())
        row.update({k: sim_json.get(k) for k in SIM_FIELDS}, simulated=True)
    return row


def space_row_from_files(task: TrialTask, out_dir: Path) -> dict:
    """A trial in space's row, read back from the plan.json planning.spatial.save_space_plan wrote."""
    row = empty_row(task)
    plan_json = json.loads((out_dir / PLAN_JSON).read_text())
    row.update({k: plan_json.get(k) for k in PLAN_FIELDS})
    check, error = plan_json.get("physics_check"), plan_json.get("final_error_rad")
    row["converged"] = bool(plan_json["segments"]) and all(s["success"] for s in plan_json["segments"])
    row["check_passed"] = None if check is None else bool(check["passed"])
    row["final_error_deg"] = None if error is None else math.degrees(error)
    row["plan_arrays"] = (out_dir / PLAN_NPZ).is_file()
    row["switching_fingers"] = [n.get("switching_finger") for n in plan_json["contact_plan"]["contact_sequence"]]
    row.update({k: plan_json["contact_plan"].get(k) for k in ("margin_stances", "stances")})
    sim_path = out_dir / SIM_JSON
    if sim_path.is_file():
        sim_json = json.loads(sim_path.read_text())
        row.update({k: sim_json.get(k) for k in ("dropped", "drop_time_s", "sim_time_s", *SPACE_SIM_FIELDS)})
        row["simulated"] = True
    return row


def run_space_trial(task: TrialTask, out_dir: Path) -> dict:
    """Plans the task's goal quaternion with a hand in space (planning.spatial: plan_space, or plan_space_cito for
    the baselines), its segments one after another in this process, and writes plan.json (and plan.npz); with
    `simulate`, executes a plan with arrays open loop in its own world (execution.space_run) into sim.json and
    sim.npz."""
    from trajectotree.config import config_from_dict
    from trajectotree.planning.spatial import plan_space, plan_space_cito, save_space_plan
    from trajectotree.scene.spatial import build_space_scene

    config = config_from_dict(task.config)
    scene = build_space_scene(config.scene.hand, mu=config.scene.mu, gravity=config.scene.gravity, **task.space)
    if task.method == "trajectotree":
        result = plan_space(scene, task.goal, config, workers=1)
    else:
        result = plan_space_cito(scene, task.goal, config, task.method, workers=1)
    save_space_plan(result, out_dir, config)
    if task.simulate and (out_dir / PLAN_NPZ).is_file():
        from trajectotree.execution.space_plan import load_space_plan, save_space_sim
        from trajectotree.execution.space_run import simulate_space

        plan = load_space_plan(out_dir, config)
        save_space_sim(simulate_space(plan.reference, config, plan.scene), out_dir, plan.success)
    return space_row_from_files(task, out_dir)


def run_trial(task: TrialTask, out_dir: Path) -> dict:
    """Plans (and executes) the task in this process, writing plan.json/.npz (and
    sim.json/.npz) into out_dir. Returns the row. Normal failures (no contact plan,
    IPOPT not converged, a drop) are results in the files, not exceptions."""
    if task.space is not None:
        return run_space_trial(task, out_dir)
    from trajectotree.config import config_from_dict
    from trajectotree.io import save_plan, save_sim
    from trajectotree.planning.planners import plan
    from trajectotree.scene.plant import build_scene

    config = config_from_dict(task.config)
    scene = build_scene(config.scene)
    # The sweep runs trials in parallel already: a trial solves its keyframes segments serially.
    result = plan(scene=scene, goal=task.goal, method=task.method, config=config, segment_workers=1)
    save_plan(result, out_dir)
    if task.simulate and result.trajectory is not None:
        from trajectotree.execution.run import run_simulation

        save_sim(run_simulation(plan=result, config=config), out_dir)
    return row_from_files(task, out_dir)


def _signal_name(returncode: int) -> str:
    try:
        return signal.Signals(-returncode).name
    except ValueError:
        return f"signal {-returncode}"


def _error_outcome(task: TrialTask, error: str, wall_s: float, log: str) -> TrialOutcome:
    row = empty_row(task)
    row.update(error=error, trial_wall_s=wall_s)
    files = {ROW_FILE: json.dumps(row, indent=2).encode()}
    if log:
        files[LOG_FILE] = log.encode()
    return TrialOutcome(row=row, files=files)


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else ""


def execute_trial(
    task: TrialTask, scratch_root: str | None = None, children: TrialChildren | None = None
) -> TrialOutcome:
    """Runs the task in a child process with its time limit; returns its files.
    A child that raises, crashes or runs out of time gives a row with `error` set.
    The child's scratch folder is made in scratch_root (default: the system's temp folder);
    `children` (when given) holds the child while it runs, so its sweep can stop it."""
    children = TrialChildren() if children is None else children
    if children.stopping:
        raise TrialInterrupted(task.key)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=f"{SCRATCH_PREFIX}{task.key}-", dir=scratch_root) as scratch:
        out_dir, tmp_dir = Path(scratch) / "out", Path(scratch) / "tmp"
        out_dir.mkdir()
        tmp_dir.mkdir()
        # One OpenMP thread for SPRAL unless the user chose otherwise: trials run side by side anyway,
        # and a threaded factorization may round differently from run to run (same trial, same result).
        env = {**os.environ, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1"), "TMPDIR": str(tmp_dir)}
        child = subprocess.Popen(
            [sys.executable, "-m", "trajectotree.experiments.trial", scratch],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        children.add(child)
        try:
            try:
                out, err = child.communicate(json.dumps(asdict(task)), timeout=task.time_limit_s)
                timed_out = False
            except subprocess.TimeoutExpired:
                child.kill()
                out, err = child.communicate()
                timed_out = True
        finally:
            children.discard(child)
        wall_s = time.perf_counter() - start
        log = (out + err)[-STDERR_TAIL_CHARS:]
        if children.stopping or child.returncode in (-signal.SIGINT, -signal.SIGTERM):
            raise TrialInterrupted(task.key)
        if timed_out:
            return _error_outcome(
                task, f"timeout: exceeded the trial time limit of {task.time_limit_s:g} s", wall_s, log
            )
        if child.returncode < 0:
            return _error_outcome(
                task, f"crashed: the trial process died from {_signal_name(child.returncode)}", wall_s, log
            )
        if child.returncode != 0:
            return _error_outcome(
                task, _last_line(err) or f"the trial process exited with code {child.returncode}", wall_s, log
            )
        files = {p.name: p.read_bytes() for p in sorted(out_dir.iterdir()) if p.is_file()}
    row = json.loads(files[ROW_FILE])
    row["trial_wall_s"] = wall_s
    files[ROW_FILE] = json.dumps(row, indent=2).encode()
    if log.strip():
        files[LOG_FILE] = log.encode()
    return TrialOutcome(row=row, files=files)


def _exit_with_parent(parent_pid: int, scratch: Path) -> None:
    """Ends this child, removing its scratch folder, once its sweep process is gone
    (killed with SIGKILL), so no orphaned trial keeps a core busy."""
    while os.getppid() == parent_pid:
        time.sleep(1.0)
    shutil.rmtree(scratch, ignore_errors=True)
    os._exit(1)


def main(argv: list[str]) -> int:
    """Child entry point: task JSON on stdin, files into argv[0]/out."""
    scratch = Path(argv[0])
    out_dir = scratch / "out"
    out_dir.mkdir(exist_ok=True)
    threading.Thread(target=_exit_with_parent, args=(os.getppid(), scratch), daemon=True).start()
    task = TrialTask(**json.loads(sys.stdin.read()))
    row = run_trial(task, out_dir)
    (out_dir / ROW_FILE).write_text(json.dumps(row, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
