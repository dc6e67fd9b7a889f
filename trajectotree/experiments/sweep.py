"""The paper's experiment (Sec. IV): random goal rotations x methods, run as a resumable sweep.

A sweep directory holds
  manifest.json          what the sweep is (goals, methods, simulate, the full config, and the
                         latest run's time limit); rerunning with other arguments in the same
                         directory is an error, except --time-limit (not part of a trial's identity)
  trials/<i>_<method>/   one finished trial: trial.json (its row), plan.json + plan.npz,
                         sim.json + sim.npz with --simulate, log.txt when the child printed
  trials/.tmp-*          a running trial's scratch (its files and its TMPDIR, e.g. IPOPT's log)
                         and trials being stored; removed when the sweep starts again
  trials.jsonl           one JSON row per finished trial (rebuilt from trials/ on every run)
  corrupt/               trials whose trial.json could not be read, moved aside (then recomputed)
  .lock                  held (flock) by the running sweep, with its pid; a second sweep on the
                         same directory is refused; the kernel releases it when its holder dies

Trials run on an executor: local worker processes (`workers` at a time), or a Dask
cluster (`scheduler` address). Either way each trial is its own child process
(trajectotree.experiments.trial) and only this process writes into the directory: a trial's
directory is assembled under a temporary name and renamed into place, so a killed
sweep leaves no partial trial, and the rerun skips every finished one. The directory's
own code (manifest, lock, rows, storing) is in trajectotree.experiments.sweep_store.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor, as_completed
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trajectotree.config import Config, ConfigError, check_integer, check_range, config_to_dict
from trajectotree.experiments.sweep_store import (
    TRIALS_DIR,  # noqa: F401
    check_manifest,
    prepare_dir,
    read_rows,
    store_trial,
    sweep_lock,
    write_rows_file,
)
from trajectotree.experiments.trial import (
    ROW_FILE,
    TrialChildren,
    TrialInterrupted,
    TrialOutcome,
    TrialTask,
    empty_row,
    execute_trial,
)
from trajectotree.results import METHODS  # results imports no Drake, like this module

MANIFEST_FORMAT = "trajectotree-sweep/1"


def sample_goals(count: int, seed: int, max_abs: float = math.pi) -> np.ndarray:
    """`count` goal rotations (rad) drawn uniformly from [-max_abs, max_abs] with `seed`.
    The same seed always gives the same goals (paper Sec. IV-A: 60 goals in [-pi, pi])."""
    return np.random.default_rng(seed).uniform(-max_abs, max_abs, count)


def sample_space_goals(count: int, seed: int, max_angle: float = math.pi) -> np.ndarray:
    """(count, 4) goal orientations [w, x, y, z] uniform over SO(3) with `seed` (scipy's Rotation.random, as
    scripts/bench_space.py draws them), or, with max_angle (rad) under pi, uniform over the rotations at most
    max_angle from the start orientation (the identity): the uniform ones drawn in turn, those beyond it rejected."""
    from scipy.spatial.transform import Rotation

    if max_angle >= math.pi:
        return Rotation.random(count, random_state=seed).as_quat(scalar_first=True)
    rng = np.random.default_rng(seed)
    kept = np.empty((0, 4))
    while len(kept) < count:  # the accepted share is (a - sin a) / pi: 4e-4 at 0.2 rad, 1e5 draws a batch
        batch = Rotation.random(100_000, random_state=rng)
        kept = np.vstack([kept, batch[batch.magnitude() <= max_angle].as_quat(scalar_first=True)])
    return kept[:count]


AXIS_ALIGNED_GOALS = 23  # the cube's rotation group (24) but the identity


def axis_aligned_goals() -> np.ndarray:
    """(23, 4) [w, x, y, z]: the cube's 24 rotations but the identity (MuJoCo MPC's task), applied to the start
    orientation in W."""
    from scipy.spatial.transform import Rotation

    from trajectotree.scene.spatial import START_POSE

    start = Rotation.from_quat(START_POSE[:4], scalar_first=True)
    group = [r for r in Rotation.create_group("O") if r.magnitude() > 1e-9]
    return np.array([(r * start).as_quat(scalar_first=True) for r in group])


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep computes; equal specs give identical trials (its manifest)."""

    goals: int  # number of goal rotations
    seed: int  # seed of the goal sampler
    methods: tuple[str, ...] = METHODS  # planners to compare
    simulate: bool = False  # execute every plan that has a trajectory
    config: Config = field(default_factory=Config)
    max_goal: float = math.pi  # rad, goals are uniform in [-max_goal, max_goal] (space: at most max_goal from start)
    time_limit_s: float = 1800.0  # s, per trial (plan + simulation); a trial past it is killed
    space: SpaceSweepObject | None = None  # a hand in space (config.scene.hand) and its box; None: planar
    axis_aligned: bool = False  # in space: the first `goals` of the 23 axis-aligned orientations, not random ones

    def __post_init__(self):
        check_integer("--goals", self.goals, 1, 100000)
        check_integer("--seed", self.seed, 0, 2**63 - 1)
        if not self.methods:
            raise ConfigError(f"--methods is empty; valid methods: {', '.join(METHODS)}")
        for method in self.methods:
            if method not in METHODS:
                raise ConfigError(f"--methods: unknown method {method!r}; valid methods: {', '.join(METHODS)}")
        if len(set(self.methods)) != len(self.methods):
            raise ConfigError(f"--methods {' '.join(self.methods)} names a method twice")
        check_range("--max-goal", self.max_goal, 0.0, math.pi, low_open=True)
        check_range("--time-limit", self.time_limit_s, 0.0, None, low_open=True)
        if self.axis_aligned:
            if self.space is None:
                raise ConfigError("--axis-aligned: the axis-aligned orientations are goals of a hand in space")
            check_integer("--goals", self.goals, 1, AXIS_ALIGNED_GOALS)

    def goal_values(self) -> np.ndarray:
        """(goals,) rad for a planar hand, (goals, 4) quaternions [w, x, y, z] for a hand in space."""
        if self.axis_aligned:
            return axis_aligned_goals()[: self.goals]
        if self.space is not None:
            return sample_space_goals(self.goals, self.seed, self.max_goal)
        return sample_goals(self.goals, self.seed, self.max_goal)

    def manifest(self) -> dict:
        # a planar sweep's manifest has no "space" key, so sweeps made before hands in space resume as they were
        space = {} if self.space is None else {"space": self.space.to_json()}
        space |= {"axis_aligned": True} if self.axis_aligned else {}  # random goals' manifests as they were
        return space | {
            "format": MANIFEST_FORMAT,
            "goals": self.goals,
            "seed": self.seed,
            "max_goal": self.max_goal,
            "goal_values": self.goal_values().tolist(),
            "methods": list(self.methods),
            "simulate": self.simulate,
            "time_limit_s": self.time_limit_s,
            "config": config_to_dict(self.config),
        }

    def tasks(self) -> list[TrialTask]:
        """Goal-major order, so partial results cover every method."""
        config = config_to_dict(self.config)
        return [
            TrialTask(
                key=trial_key(i, m),
                goal_index=i,
                goal=g.tolist(),
                method=m,
                simulate=self.simulate,
                config=config,
                time_limit_s=self.time_limit_s,
                space=None if self.space is None else self.space.to_json(),
            )
            for i, g in enumerate(self.goal_values())
            for m in self.methods
        ]


@dataclass(frozen=True)
class SpaceSweepObject:
    """The box a sweep in space plans: its size (x, y, z) m and mass kg as given, else (None) the hand's own."""

    size: tuple[float, float, float] | None = None
    mass: float | None = None

    def to_json(self) -> dict:
        return {"size": None if self.size is None else [float(v) for v in self.size], "mass": self.mass}


def trial_key(goal_index: int, method: str) -> str:
    return f"{goal_index:04d}_{method}"


# ---- executors -----------------------------------------------------------------------


def connect_scheduler(address: str, timeout_s: float):
    """A dask.distributed Client for `address`; ConfigError if Dask is missing or the
    scheduler does not answer within timeout_s."""
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError("--scheduler needs dask.distributed: pip install 'trajectotree[distributed]'") from None
    try:
        return Client(address, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError) as e:
        raise ConfigError(
            f"--scheduler {address!r}: cannot reach the Dask scheduler within {timeout_s:g} s ({type(e).__name__}: {e})"
        ) from None


def _local_results(tasks: list[TrialTask], workers: int, scratch_root: str | None = None):
    """Yields (task, outcome or exception) as trials finish on `workers` local processes,
    each with its scratch folder under scratch_root (default: the system's temp folder)."""
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="trial")
    children = TrialChildren()
    completed = False
    try:
        futures = {pool.submit(execute_trial, t, scratch_root, children): t for t in tasks}
        for future in as_completed(futures):
            yield futures[future], _result_or_error(future)
        completed = True
    finally:
        if not completed:  # interrupted: stop the running trials, start no queued one
            children.stop()
        pool.shutdown(wait=True, cancel_futures=True)


def _dask_results(tasks: list[TrialTask], client):
    from distributed import as_completed as dask_as_completed

    futures = {}
    for t in tasks:
        futures[client.submit(execute_trial, t, key=f"trajectotree-trial-{t.key}-{time.time_ns()}", pure=False)] = t
    try:
        for future in dask_as_completed(futures):
            yield futures[future], _result_or_error(future)
    finally:
        client.cancel(list(futures))


def _result_or_error(future):
    """The TrialOutcome, or the exception: TrialInterrupted, or the executor's own
    failure (a lost Dask worker, a process that could not start)."""
    try:
        return future.result()
    except Exception as e:
        return e


# ---- the sweep ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SweepSummary:
    out_dir: str
    total: int  # trials in the sweep
    skipped: int  # finished before this run
    ran: int  # finished in this run
    errors: int  # trials recorded with an error (all runs)
    wall_s: float  # s, this run
    solved: dict[str, int]  # method -> successful plans (all runs)
    per_method: dict[str, int]  # method -> finished trials (all runs)
    dropped: dict[str, int]  # method -> simulated drops (all runs)

    def line(self) -> str:
        methods = ", ".join(
            f"{m} {self.solved.get(m, 0)}/{n} solved" + (f" {self.dropped[m]} dropped" if m in self.dropped else "")
            for m, n in self.per_method.items()
        )
        done = self.skipped + self.ran
        return (
            f"sweep {self.out_dir}: {done}/{self.total} trials done ({self.ran} now, {self.skipped} before) "
            f"in {self.wall_s:.1f} s; {methods}; {self.errors} errors"
        )


def summarize_rows(out_dir: Path, spec: SweepSpec, skipped: int, ran: int, wall_s: float) -> SweepSummary:
    rows = read_rows(out_dir)
    per_method = Counter(r["method"] for r in rows)
    return SweepSummary(
        out_dir=str(out_dir),
        total=spec.goals * len(spec.methods),
        skipped=skipped,
        ran=ran,
        errors=sum(r.get("error") is not None for r in rows),
        wall_s=wall_s,
        solved=dict(Counter(r["method"] for r in rows if r.get("success"))),
        per_method={m: per_method[m] for m in spec.methods if per_method[m]},
        dropped={
            m: sum(bool(r.get("dropped")) for r in rows if r["method"] == m)
            for m in spec.methods
            if spec.simulate and per_method[m]
        },
    )


def pending_tasks(out_dir: Path, spec: SweepSpec, retry_errors: bool) -> tuple[list[TrialTask], int]:
    finished = {r["key"]: r for r in read_rows(out_dir)}
    keep = {k for k, r in finished.items() if not (retry_errors and r.get("error") is not None)}
    tasks = [t for t in spec.tasks() if t.key not in keep]
    return tasks, len(spec.tasks()) - len(tasks)


def check_executor(workers: int | None, scheduler: str | None, scheduler_timeout_s: float) -> int:
    if workers is not None and scheduler is not None:
        raise ConfigError(
            "--workers sets local worker processes; with --scheduler the cluster's workers run "
            "the trials: give one or the other"
        )
    check_range("--scheduler-timeout", scheduler_timeout_s, 0.0, None, low_open=True)
    if workers is None:
        return os.cpu_count() or 1
    check_integer("--workers", workers, 1, 4096)
    return workers


def run_sweep(
    spec: SweepSpec,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    scheduler_timeout_s: float = 30.0,
    retry_errors: bool = False,
    progress: bool = True,
) -> SweepSummary:
    """Runs every unfinished trial of `spec` into out_dir and returns the summary.
    Invalid input raises ConfigError before anything is written."""
    out_dir = Path(out_dir)
    workers = check_executor(workers, scheduler, scheduler_timeout_s)
    check_manifest(out_dir, spec, locked=False)  # a refusal that writes nothing (not even the lock file)
    client = connect_scheduler(scheduler, scheduler_timeout_s) if scheduler else None
    start = time.perf_counter()
    try:
        with sweep_lock(out_dir):
            return _run_locked(spec, out_dir, client, workers, retry_errors, progress, start)
    finally:
        if client is not None:
            client.close()


def _run_locked(
    spec: SweepSpec, out_dir: Path, client, workers: int, retry_errors: bool, progress: bool, start: float
) -> SweepSummary:
    from tqdm import tqdm

    for message in prepare_dir(out_dir, spec):
        print(f"sweep {out_dir}: {message}", file=sys.stderr)
    write_rows_file(out_dir)  # drops a line torn by a kill
    tasks, skipped = pending_tasks(out_dir, spec, retry_errors)
    scratch = str(out_dir / TRIALS_DIR)  # trials' scratch folders (.tmp-scratch-*), cleaned on every start
    results = _dask_results(tasks, client) if client else _local_results(tasks, workers, scratch)
    ran = 0
    bar = tqdm(
        total=skipped + len(tasks),
        initial=skipped,
        unit="trial",
        desc="sweep",
        disable=not progress,
        dynamic_ncols=True,
    )
    with closing(results), bar:
        for task, outcome in results:
            if isinstance(outcome, TrialInterrupted):
                continue
            if isinstance(outcome, Exception):
                outcome = executor_error(task, outcome)
            store_trial(out_dir, outcome)
            ran += 1
            bar.update(1)
            if outcome.row.get("error") is not None:
                bar.write(f"{task.key}: {outcome.row['error']}")
    write_rows_file(out_dir)
    return summarize_rows(out_dir, spec, skipped, ran, time.perf_counter() - start)


def executor_error(task: TrialTask, error: Exception) -> TrialOutcome:
    row = dict(empty_row(task), error=f"executor: {type(error).__name__}: {error}")
    return TrialOutcome(row=row, files={ROW_FILE: json.dumps(row, indent=2).encode()})
