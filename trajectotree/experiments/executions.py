"""Executing a sweep's plans under several controllers and robustness conditions.

A plan does not depend on how it is executed, so a sweep plans each (goal, method) once
and this module executes every saved plan again for each (executor, condition) pair,
resumably: `trials/<key>/exec/<executor>_<condition>/sim.json` (+ `sim.npz`; config.executor.Executor's
names). Adding an executor or a condition to a finished sweep runs only the new executions.

The conditions are trajectotree.experiments.conditions'; the executions' tables,
trajectotree.experiments.execution_report's.

Executions with the closed loop (the executor `grasp-closed-loop`: the grasp controller with the contact
watch, the estimates and the reflexes, trajectotree.execution.closed_loop) are kept and listed apart,
beside the open-loop `grasp`; those that also replan from the measured state (trajectotree.execution.replan)
as `grasp-replan`.

A sweep in space's plans (plan.json `kind: space`) execute the same way, by trajectotree.execution.space_run in
the worlds of conditions.SPACE_SPEC (`execute_space`), with the executors space has (space_run.SPACE_EXECUTORS).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import threading
from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from trajectotree.config import ConfigError, ControllerGains, SimConfig
from trajectotree.config.executor import Executor, parse_executor
from trajectotree.experiments.conditions import CONDITIONS, DEFAULT_SPEC, ConditionSpec, check_condition
from trajectotree.experiments.sweep_store import TRIALS_DIR, sweep_lock
from trajectotree.io import PLAN_JSON, PLAN_NPZ, SIM_JSON, SIM_NPZ, npz_problem, write_bytes_atomic
from trajectotree.planning.workers import kill_pool, process_pool

EXEC_DIR = "exec"
PAPER_EXECUTORS = (Executor.GRASP, Executor.PAPER)  # the paper's: its controller and eq. 20, open loop


def execution_dir(trial_dir: str | Path, executor: Executor | str, condition: str) -> Path:
    """The folder of a trial's execution by `executor` (an Executor or its name) under `condition`."""
    return Path(trial_dir) / EXEC_DIR / f"{parse_executor(executor).value}_{condition}"


@dataclass(frozen=True)
class ExecutionTask:
    trial_dir: str  # the sweep trial's folder (plan.json, plan.npz)
    executor: Executor  # a replanning one plans its segments in this process
    condition: str  # CONDITIONS
    spec: ConditionSpec
    # The executor's gains and simulation settings; None: those saved with the plan.
    gains: ControllerGains | None = None
    sim: SimConfig | None = None

    @property
    def folder(self) -> Path:
        return execution_dir(self.trial_dir, self.executor, self.condition)


def execute(task: ExecutionTask) -> dict:
    """Loads the trial's plan, executes it, writes sim.json + sim.npz into its execution
    folder; returns sim.json's content."""
    if is_space_trial(Path(task.trial_dir)):
        return execute_space(task)
    from trajectotree.execution.run import run_simulation
    from trajectotree.io import load_plan, save_sim

    plan = load_plan(task.trial_dir)
    config = replace(
        plan.config,
        controller=task.gains or plan.config.controller,
        sim=task.sim or plan.config.sim,
    )
    duration = float(plan.trajectory.t[-1] - plan.trajectory.t[0])
    result = run_simulation(
        plan=plan,
        config=config,
        executor=task.executor,
        segment_workers=1,  # a replan's later segments in this process: the sweep runs one execution per core
        **task.spec.simulation_kwargs(task.condition, config, duration),
    )
    out = task.folder
    save_sim(result, out)
    return read_execution(out)


def is_space_trial(trial_dir: Path) -> bool:
    """Whether the trial's plan.json holds a plan in space (an unreadable one: no)."""
    try:
        return json.loads((trial_dir / PLAN_JSON).read_text()).get("kind") == "space"
    except (OSError, ValueError, AttributeError):
        return False


def execute_space(task: ExecutionTask) -> dict:
    """execute() of a plan in space: its reference and scene from the trial's folder, the executor's gains and
    simulation settings on the plan's config, the condition's world (ConditionSpec.space_world) in the plant."""
    from trajectotree.execution.space_plan import load_space_plan, save_space_sim
    from trajectotree.execution.space_run import simulate_space

    plan = load_space_plan(task.trial_dir)
    config = replace(plan.config, controller=task.gains or plan.config.controller, sim=task.sim or plan.config.sim)
    world = task.spec.space_world(
        task.condition, config, plan.scene.object.mass, plan.reference.duration, plan.segments
    )
    result = simulate_space(
        plan.reference,
        config,
        plan.scene,
        executor=task.executor,
        conditions=world,
        goal=plan.data.get("goal_quaternion"),
        segment_workers=1,  # a replan's segments in this process: the sweep runs one execution per core
    )
    save_space_sim(result, task.folder, plan.success)
    return read_execution(task.folder)


def read_execution(folder: Path) -> dict:
    """An execution's sim.json; ConfigError naming it when it cannot be read."""
    path = Path(folder) / SIM_JSON
    try:
        data = json.loads(path.read_text())
        if not isinstance(data, dict):
            raise ValueError("not a JSON object")
    except (OSError, UnicodeDecodeError, ValueError) as e:  # JSONDecodeError is a ValueError
        raise ConfigError(
            f"{str(path)!r} is unreadable ({type(e).__name__}: {e}); rerun the sweep with the same "
            "--controllers and --conditions to recompute it"
        ) from None
    return data


def execution_problem(folder: Path) -> str | None:
    """Why an execution folder holds no finished execution (sim.json or sim.npz missing or
    unreadable), or None when it does: such an execution is pending, and is run again."""
    try:
        read_execution(folder)
    except ConfigError as e:
        return str(e)
    problem = npz_problem(Path(folder) / SIM_NPZ)
    return None if problem is None else f"{str(Path(folder) / SIM_NPZ)!r} is unreadable ({problem})"


def pending_executions(
    sweep_dir: str | Path,
    executors,
    conditions,
    spec: ConditionSpec,
    methods=None,
    gains: ControllerGains | None = None,
    sim: SimConfig | None = None,
) -> list[ExecutionTask]:
    """Every (trial with a trajectory, of `methods` (None: all), executor (an Executor or its name),
    condition) without a finished execution. A nominal open-loop execution the sweep's own --simulate
    already ran (the trial's sim.json, same controller) is copied instead of rerun."""
    executors = [parse_executor(e) for e in executors]
    conditions = [check_condition(c, spec) for c in conditions]
    tasks = []
    for trial_dir in sorted(p for p in (Path(sweep_dir) / TRIALS_DIR).iterdir() if p.is_dir()):
        try:
            plan = json.loads((trial_dir / PLAN_JSON).read_text())
        except (json.JSONDecodeError, OSError):
            continue  # not a finished trial (the sweep names and recomputes a corrupt one)
        # a plan in space has a trajectory where plan.npz was written (planning.spatial.save_space_plan)
        solved = (trial_dir / PLAN_NPZ).is_file() if plan.get("kind") == "space" else plan.get("iterations")
        if not solved or (methods is not None and plan.get("method") not in methods):
            continue  # nothing was solved (no trajectory to execute), or not asked for
        # Compared as saved: a key the plan's file lacks (saved before the field existed) loads as
        # today's default, but the sweep's simulation did not run with it.
        saved = plan["config"]
        same_settings = (gains is None or _as_saved(gains) == saved.get("controller")) and (
            sim is None or {**_as_saved(sim), "controller": None} == {**saved.get("sim", {}), "controller": None}
        )
        for executor in executors:
            for condition in conditions:
                task = ExecutionTask(str(trial_dir), executor, condition, spec, gains, sim)
                if execution_problem(task.folder) is None or (
                    same_settings
                    and not executor.closed_loop
                    and _reuse_sweep_simulation(trial_dir, executor, condition, task.folder)
                ):
                    continue
                tasks.append(task)
    return tasks


def _as_saved(settings) -> dict:
    """A config dataclass as plan.json holds it (JSON types: lists for tuples)."""
    return json.loads(json.dumps(asdict(settings)))


def _reuse_sweep_simulation(trial_dir: Path, executor: Executor, condition: str, out: Path) -> bool:
    """Copies the trial's own sim.json/sim.npz into `out` when they are this nominal open-loop execution (a
    planar sim.json names its controller, one in space its executor)."""
    try:
        sim = json.loads((trial_dir / SIM_JSON).read_text())
    except (OSError, json.JSONDecodeError):
        return False
    nominal = not sim.get("conditions") or (
        sim["conditions"].get("push") is None
        and sim["conditions"].get("sim_mu") == sim["conditions"].get("plan_mu")
        and sim["conditions"].get("sim_mass") == sim["conditions"].get("plan_mass")
    )
    if (
        condition != "nominal"
        or sim.get("executor", sim.get("controller")) != executor.value
        or sim.get("closed_loop") is not None  # a closed-loop run (an open-loop sim.json has None or lacks it)
        or not nominal
        or npz_problem(trial_dir / SIM_NPZ) is not None  # a torn copy would pass for a finished execution
    ):
        return False
    write_bytes_atomic(out / SIM_NPZ, (trial_dir / SIM_NPZ).read_bytes())  # npz first: sim.json marks it done
    write_bytes_atomic(out / SIM_JSON, (trial_dir / SIM_JSON).read_bytes())
    return True


def run_executions(
    sweep_dir: str | Path,
    *,
    executors=PAPER_EXECUTORS,
    conditions=CONDITIONS,
    spec: ConditionSpec = DEFAULT_SPEC,
    methods=None,
    gains: ControllerGains | None = None,
    sim: SimConfig | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> int:
    """Runs the pending executions of a sweep's plans (of `methods`, None: all) by each of `executors`
    with the controller `gains` and `sim` settings (None: those saved with each plan), on `workers`
    local processes, holding the
    sweep's lock; returns how many ran. A failed execution is reported on stderr and left
    pending (rerun to retry); the others go on."""
    sweep_dir = Path(sweep_dir)
    if not (sweep_dir / TRIALS_DIR).is_dir():
        raise ConfigError(f"{str(sweep_dir)!r} is not a sweep directory (no {TRIALS_DIR}/)")
    with sweep_lock(sweep_dir):
        tasks = pending_executions(sweep_dir, executors, conditions, spec, methods, gains, sim)
        if not tasks:
            return 0
        for line in torn_executions(tasks):
            print(line, file=sys.stderr)
        bar = None
        if progress and sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=len(tasks), desc="executions", unit="run")
        done = 0
        # Fresh interpreters (spawn), not forks of a process that may hold Drake's threads.
        pool = process_pool(workers or os.cpu_count() or 1, "spawn")
        try:
            with _stop_signals_deferred():  # the pool spawns its workers while the tasks are submitted
                futures = {pool.submit(execute, t): t for t in tasks}
            for future in as_completed(futures):
                task = futures[future]
                try:
                    future.result()
                    done += 1
                except BrokenProcessPool:
                    raise  # the workers themselves died: every other execution would fail the same way
                except Exception as e:  # one broken plan must not stop the others
                    print(
                        f"execution {Path(task.trial_dir).name} {task.executor.value}/{task.condition} failed: "
                        f"{type(e).__name__}: {e}",
                        file=sys.stderr,
                    )
                if bar is not None:
                    bar.update()
        except BaseException:
            kill_pool(pool)  # interrupted (Ctrl-C, SIGTERM) or broken: run no queued execution, stop the running
            raise
        pool.shutdown()
        if bar is not None:
            bar.close()
        return done


def torn_executions(tasks: list[ExecutionTask]) -> list[str]:
    """What to say of each pending task whose own folder (this executor's) holds files: a finished
    execution is not pending, so those files are torn, and the execution is recomputed."""
    return [
        f"execution {task.folder}: {execution_problem(task.folder)}; it is recomputed"
        for task in tasks
        if task.folder.is_dir() and any(task.folder.iterdir())
    ]


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _stop_signals_deferred():
    """Defers Ctrl-C and SIGTERM to the end of the block, where they act as usual: one that
    interrupted a spawn between starting a worker and sending it its start-up data would leave that
    worker out of the pool, to die later with a traceback on the sweep's stderr. (Masking the
    signals would not do: numpy's threads would take them.)"""
    if threading.current_thread() is not threading.main_thread():
        yield  # Python runs signal handlers in the main thread only: nothing here to defer
        return
    received: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: received.append(signum)) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        if received:
            signal.raise_signal(received[0])


def collect_executions(sweep_dir: str | Path, rows: list[dict]) -> list[dict]:
    """One record per finished execution of the sweep's trials: method, goal, controller (the
    executor label: grasp-closed-loop for the closed loop), condition and the sim.json metrics."""
    records = []
    for row in rows:
        base = Path(sweep_dir) / TRIALS_DIR / row["key"] / EXEC_DIR
        if not base.is_dir():
            continue
        for folder in sorted(base.iterdir()):
            if (folder / SIM_JSON).is_file():
                controller, _, condition = folder.name.partition("_")
                # The folder names the executor: sim.json's "controller" is grasp with the closed loop too.
                records.append(
                    {
                        **read_execution(folder),
                        "key": row["key"],
                        "method": row["method"],
                        "goal": row["goal"],
                        "controller": controller,
                        "condition": condition,
                        "folder": str(folder),
                    }
                )
    return records
