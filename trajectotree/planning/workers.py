"""The package's local worker processes (the keyframes formulation's segment workers, a sweep's
executions): pools whose workers live no longer than the process that started them, and leave the
decision to stop to it.

- A worker dies with its parent, however the parent ends (SIGKILL from the OOM killer, `timeout -s
  KILL` or a scheduler included, where no clean-up of the parent's runs): on Linux the kernel sends
  it SIGKILL then (prctl PR_SET_PDEATHSIG), elsewhere a watchdog thread polls the parent's pid.
- Ctrl-C reaches the terminal's whole process group: a worker ignores SIGINT, and SIGTERM ends it
  (a forked worker would otherwise inherit the CLI's handlers); its parent decides and kills it
  (kill_pool). Both are blocked from the fork until the worker has set them, so no stop reaches a
  worker still starting, which would print a traceback.
- A forked worker holds none of its parent's files: its copies of the descriptors the parent had
  open as it forked point at /dev/null instead. A kept pool's workers live as long as the parent, and
  a pipe end they held would keep its reader from ever seeing the end of the file: a subprocess the
  parent started before (a browser driver reading its stdin) would never exit once told to.

Drake-free (it imports nothing of the package): the sweep's process, which never loads Drake,
makes its execution pool here too.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Mapping
from concurrent.futures import ProcessPoolExecutor

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>: the signal a process gets when its parent thread dies
PARENT_POLL_S = 0.5  # s, how often the watchdog (no PR_SET_PDEATHSIG) checks the parent's pid
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class TiedPool(ProcessPoolExecutor):
    """A ProcessPoolExecutor whose workers start with the stop signals blocked (see the module doc).

    Its workers are started by the thread that submits (all at the first submit when forked, one
    per submit when spawned), and PR_SET_PDEATHSIG fires when that *thread* ends: the thread that
    submits must outlive the pool. The package's pools are made, used and killed or shut down
    within one call of one thread (segment_pool.run_on_pool, executions.run_executions), which cannot
    end before them; a pool from segment_pool.local_pool passed to plan() is the caller's to submit to
    from a thread that lives as long (the main thread always does)."""

    def __init__(self, workers: int, start_method: str):
        # The parent's open files as its workers fork (descriptor -> identity, filled by submit); a
        # forked worker lets go of them. Its own pipes (the task and result queues), opened below, stay.
        self._parent_files: dict[int, tuple[int, int]] = {}
        self._forks = start_method == "fork"
        before = _open_files()
        super().__init__(
            workers,
            mp_context=multiprocessing.get_context(start_method),
            initializer=_start_worker,
            initargs=(os.getpid(), self._parent_files),
        )
        self._own_files = _open_files().items() - before.items()

    def submit(self, fn, /, *args, **kwargs):
        with _stops_blocked():  # a worker forked or spawned here inherits the mask
            if self._forks:  # the workers fork within a submit (all at the first)
                self._parent_files.clear()
                self._parent_files.update(_open_files().items() - self._own_files)
            return super().submit(fn, *args, **kwargs)


def process_pool(workers: int, start_method: str) -> TiedPool:
    """`workers` local processes started by `start_method` ("fork" or "spawn"), tied to this process."""
    return TiedPool(workers, start_method)


def kill_pool(pool: ProcessPoolExecutor) -> None:
    """Kills a pool's worker processes (SIGKILL: one deep in a solver would not run a handler),
    reaps them, and shuts the pool down, its queued tasks cancelled: shutdown() alone would first
    wait for the running tasks (minutes in IPOPT) and then run the queued ones."""
    # ProcessPoolExecutor has no public kill before Python 3.14 (kill_workers); its processes are _processes.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for process in processes:
        if process.is_alive():
            process.kill()
    for process in processes:
        process.join(timeout=10)
    pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def _stops_blocked():
    """SIGINT and SIGTERM blocked in this thread within the block. The process still takes them:
    Python runs its handlers in the main thread whichever thread the kernel delivers a signal to,
    and one that finds every thread blocking it waits until the block ends."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _start_worker(parent_pid: int, parent_files: Mapping[int, tuple[int, int]] | None = None) -> None:
    """A worker's initializer: the stop signals as the module doc says, its copies of `parent_files`
    (the parent's open files as it forked: descriptor -> identity) let go of, then tied to `parent_pid`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)  # blocked since the fork (TiedPool.submit)
    _let_go_of(parent_files or {})
    if not _kernel_kills_orphan():
        threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True, name="parent-watch").start()
    if os.getppid() != parent_pid:  # the parent died before the tie: the kernel's signal has gone by
        os._exit(1)


def _open_files() -> dict[int, tuple[int, int]]:
    """This process's open descriptors but stdin, stdout and stderr: descriptor -> (device, inode)."""
    files = {}
    for fd in (int(name) for name in os.listdir("/dev/fd")):
        with contextlib.suppress(OSError):  # the listing's own descriptor, closed by now
            stat = os.fstat(fd)
            if fd > 2:
                files[fd] = (stat.st_dev, stat.st_ino)
    return files


def _let_go_of(parent_files: Mapping[int, tuple[int, int]]) -> None:
    """Points each of `parent_files` that is still the same file at /dev/null. Not closed: an
    inherited object (a socket, a file) may yet close its descriptor, which must not be a reused one."""
    if not parent_files:
        return
    null = os.open(os.devnull, os.O_RDWR)
    for fd, identity in _open_files().items():
        if parent_files.get(fd) == identity:
            os.dup2(null, fd, inheritable=False)
    os.close(null)


def _kernel_kills_orphan() -> bool:
    """Asks Linux to SIGKILL this process when the thread that forked it ends; False where it cannot."""
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(None, use_errno=True)  # the C library the interpreter is linked with
    return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0


def _watch_parent(parent_pid: int) -> None:
    """Ends this process once its parent is gone (it is reparented: on macOS, to launchd). A fallback
    for platforms without PR_SET_PDEATHSIG: it polls only while this thread gets the GIL."""
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_S)
    os._exit(1)
