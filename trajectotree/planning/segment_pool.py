"""The segment pool: local worker processes that solve a plan's pieces at once (planning.piece's
`solve_piece`, or `solve_chain`: a segment with its own retries), kept by the main thread across
plans (`kept_pool`), or started for one call (`local_pool`); `run_pieces` and `run_chains` run
tasks on them, on a given executor, or in this process.
"""

from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Executor
from concurrent.futures.process import BrokenProcessPool
from typing import TypeVar

from trajectotree.cito.solve import LogObserver
from trajectotree.config import SceneConfig, check_integer
from trajectotree.planning.piece import PieceResult, PieceTask, solve_chain, solve_piece, worker_scene
from trajectotree.planning.workers import TiedPool, kill_pool, process_pool
from trajectotree.scene.plant import Scene

Task = TypeVar("Task")
Result = TypeVar("Result")

# Local worker processes start by fork where the platform has it: a child inherits the loaded
# Drake and the parent's scene (tens of ms), where spawn re-imports Drake and rebuilds the scene
# (~1-2 s, more than most segments take). scripts/bench_planning.py measures both.
START_METHOD = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"


def prepare_worker(config: SceneConfig) -> int:
    """Builds (or finds) the scene in this process; its pid (to warm up a pool, or time its start)."""
    worker_scene(config)
    return os.getpid()


def local_pool(workers: int, start_method: str = START_METHOD) -> TiedPool:
    """`workers` local processes for the segment programs, tied to this process (workers.TiedPool:
    submit to it from a thread that outlives it); reuse one across plans to pay the start-up once:
    each process keeps the scenes it solved in, worker_scene."""
    check_integer("segment workers", workers, 1)
    return process_pool(workers, start_method)


def check_workers(workers, name: str = "segment_workers") -> int | None:
    """None (as many local processes as segments and cores) or an integer >= 1 (1: serial)."""
    if workers is not None:
        check_integer(name, workers, 1)
    return workers


def run_pieces(
    tasks: list[PieceTask],
    executor: Executor | None,
    workers: int | None,
    scene: Scene | None = None,
    log_observer: LogObserver | None = None,
) -> list[PieceResult]:
    """The tasks' results in order: on `executor`, else in this process (workers 1 or one
    task; in `scene`, watched by `log_observer`), else on local processes: from the main thread
    on the pool it keeps (kept_pool: one process per core), from another on a pool of `workers`
    started for these tasks. Progress is shown only in this process: a terminal has one progress line."""
    return _run(solve_piece, tasks, executor, workers, scene, log_observer, _received)


def run_chains(
    tasks: list[PieceTask],
    executor: Executor | None,
    workers: int | None,
    scene: Scene | None = None,
    log_observer: LogObserver | None = None,
) -> list[tuple[PieceResult, ...]]:
    """Each task's chain of attempts (piece.solve_chain), in order, where run_pieces would run its piece."""
    return _run(solve_chain, tasks, executor, workers, scene, log_observer, _received_chain)


def _run(solve, tasks, executor, workers, scene, log_observer, received):
    """run_pieces with `solve` (solve_piece or solve_chain) and `received` (its results' stamp)."""
    if executor is not None:
        return [received(r) for r in executor.map(solve, tasks)]
    size = (os.cpu_count() or 1) if workers is None else workers  # a kept pool's, whatever the tasks
    workers = min(len(tasks), size)
    if workers <= 1:
        return [received(solve(t, scene, log_observer)) for t in tasks]
    for t in tasks:  # a forked worker inherits the scene built here
        worker_scene(t.scene)
    return run_on_pool(solve, tasks, size, received)


def _as_is(result):
    """A result as it came (run_on_pool's default: nothing to stamp)."""
    return result


def run_on_pool(
    solve: Callable[[Task], Result], tasks: list[Task], size: int, received: Callable[[Result], Result] = _as_is
) -> list[Result]:
    """`solve` of each of the tasks (two or more) on local processes, the results in order, each passed
    to `received` once this process has it: from the main thread on the pool it keeps (kept_pool of `size`
    processes), from another on a pool of at most `size` started for these tasks and shut down after."""
    kept = threading.current_thread() is threading.main_thread()
    pool = kept_pool(size, os.getpid()) if kept else local_pool(min(len(tasks), size))
    try:
        # Not pool.map: interrupted, its iterator cancels the queued futures, and Python 3.11's pool,
        # broken by kill_pool, then sets an exception on a cancelled future in its management thread,
        # which prints an InvalidStateError traceback (fixed in 3.12: cpython gh-107219).
        futures = [pool.submit(solve, t) for t in tasks]
        results = [received(f.result()) for f in futures]  # in order, each once it is done
    except BrokenProcessPool:
        if not kept:
            raise
        # a kept pool whose worker died since (killed from outside): the next call starts a new one
        kept_pool.cache_clear()
        return run_on_pool(solve, tasks, size, received)
    except BaseException:
        # Interrupted (Ctrl-C, or SIGTERM turned into KeyboardInterrupt by the CLI) or failed:
        # shutdown() alone would wait for the running solves, minutes deep in IPOPT.
        kill_pool(pool)
        kept_pool.cache_clear()
        raise
    if not kept:
        pool.shutdown()
    return results


@functools.lru_cache(maxsize=1)
def kept_pool(workers: int, pid: int) -> TiedPool:
    """The pool of `workers` local processes that process `pid` keeps for the segments it solves
    from its main thread: plan() called again pays no start (tens of ms per plan, issue 35). Only
    the main thread's: a pool's workers die with the thread that started them (workers.TiedPool),
    and the main thread lives as long as the process. Keyed by pid, so a forked child makes its own.
    Python's exit shuts it down, as does its eviction by a call for another size (once collected);
    run_on_pool kills it when a solve is interrupted or fails."""
    return local_pool(workers)


def _received(result: PieceResult) -> PieceResult:
    """`result` stamped with the time this process has it (no earlier than its solve ended)."""
    return dataclasses.replace(result, finished_s=time.perf_counter())


def _received_chain(chain: tuple[PieceResult, ...]) -> tuple[PieceResult, ...]:
    """Each attempt of a chain stamped with the time this process has the chain."""
    now = time.perf_counter()
    return tuple(dataclasses.replace(r, finished_s=now) for r in chain)
