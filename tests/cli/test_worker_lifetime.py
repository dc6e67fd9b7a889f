"""Worker processes live no longer than their parent, and a stop prints no traceback: `plan`
killed with SIGKILL (the OOM killer, `timeout -s KILL`, a scheduler's pre-emption), stopped by
Ctrl-C (SIGINT to the whole process group) or SIGTERM while its segment workers solve; and the
pool helper itself (trajectotree.planning.workers), forked (segments) and spawned (a sweep's
executions). Real processes throughout, each command in a session of its own."""

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from trajectotree.planning.workers import _start_worker

# The tester's command had a goal of 10 rad (~35 segments; its search alone took 5.5 s): 2 rad has 9 segments, still
# more than the workers, so segments are queued behind the running ones when the stop comes (where Python 3.11's
# pool printed its InvalidStateError traceback), and its search takes 0.1 s. Two workers whatever the machine's
# cores, so they stay queued.
LONG_PLAN = ["plan", "--goal", "2"]
WORKERS = ["--segment-workers", "2"]
GONE_WITHIN_S = 5.0  # s, a killed parent's workers must be gone by then (the kernel kills them at once)


def _stat(pid: int | str) -> list[str] | None:
    """/proc/PID/stat's fields after "pid (comm)": state, ppid, pgrp, session, ...; None when gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2 :].split()


def alive(pid: int) -> bool:
    """`pid` runs (a zombie has ended: it only waits for its new parent, init, to reap it)."""
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"


def session_processes(sid: int) -> list[int]:
    """The live processes of session `sid`: an orphaned worker keeps its session when reparented."""
    return [int(e.name) for e in Path("/proc").iterdir() if e.name.isdigit() and _in_session(e.name, sid)]


def _in_session(pid: str, sid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and int(fields[3]) == sid and fields[0] != "Z"


def cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def forked_workers(pid: int) -> list[int]:
    """`pid`'s live children running its own command line: its forked pool workers."""
    command = cmdline(pid)
    return [p for p in session_processes(pid) if int(_stat(p)[1]) == pid and command and cmdline(p) == command]


def _as_from_a_shell() -> None:
    """In the child before it runs: the stop signals' default disposition and none blocked, as a shell starts a
    command, whatever this test process's state (the state another test left in a shared xdist worker is
    inherited across fork and exec: the Ctrl-C tests timed out in the full suite, never alone)."""
    for stop in (signal.SIGINT, signal.SIGTERM):
        signal.signal(stop, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, [])


def start(args: list[str], stderr_path: Path) -> subprocess.Popen:
    """`args` in a session of its own, its stderr into a file (a surviving worker would hold a pipe open)."""
    with open(stderr_path, "w") as stderr:
        return subprocess.Popen(
            args, start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr, preexec_fn=_as_from_a_shell
        )


def wait_for_workers(child: subprocess.Popen, log: Path, count: int = 2) -> list[int]:
    """The pids of `child`'s forked workers, once `count` of them run (a bounded wait)."""
    deadline = time.monotonic() + 120
    while len(workers := forked_workers(child.pid)) < count:
        assert child.poll() is None, log.read_text()
        assert time.monotonic() < deadline, "the segment workers never started"
        time.sleep(0.05)
    return workers


def wait_gone(pids: list[int], within_s: float = GONE_WITHIN_S) -> list[int]:
    """Those of `pids` still alive after `within_s` seconds ([] as soon as all are gone)."""
    deadline = time.monotonic() + within_s
    while (left := [p for p in pids if alive(p)]) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def left_in_session(sid: int, within_s: float = GONE_WITHIN_S) -> list[int]:
    """Session `sid`'s live processes after `within_s` seconds ([] as soon as there are none): a
    spawn pool's resource tracker ends only once it reads the end of its pipe."""
    deadline = time.monotonic() + within_s
    while (left := session_processes(sid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def kill_session(child: subprocess.Popen) -> None:
    """Whatever a failed fix left running in `child`'s session, killed; `child` reaped."""
    for pid in session_processes(child.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    child.wait()


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "trajectotree.cli", *args]


def test_sigkill_of_plan_leaves_no_segment_worker_alive(tmp_path):
    out, log = tmp_path / "k", tmp_path / "stderr.txt"
    child = start(cli(*LONG_PLAN, "--out", str(out)), log)
    try:
        workers = wait_for_workers(child, log)
        child.kill()  # SIGKILL: no handler, no clean-up of the command's runs
        assert child.wait(timeout=30) == -signal.SIGKILL
        assert wait_gone(workers) == [], f"of the workers {workers}, left running"
        assert left_in_session(child.pid) == []
        # killed while planning: no plan file; SIGKILL allows no clean-up, so the folder keeps the
        # lock file of the folder lock (trajectotree.io.folder_lock), which the next command takes over
        assert sorted(p.name for p in out.iterdir()) == [".lock"]
        assert "Traceback" not in log.read_text()
    finally:
        kill_session(child)


@pytest.mark.parametrize(
    ("stop", "to_group", "code", "message"),
    [
        (signal.SIGINT, True, 130, "interrupted"),  # Ctrl-C: the terminal signals the whole group
        (signal.SIGTERM, False, 143, "terminated (SIGTERM)"),  # `kill PID`
        (signal.SIGTERM, True, 143, "terminated (SIGTERM)"),  # a scheduler stopping the job's processes
    ],
    ids=["ctrl-c", "sigterm", "sigterm-to-group"],
)
def test_a_stop_during_the_parallel_segments_prints_one_line_and_leaves_nothing(
    stop, to_group, code, message, tmp_path
):
    out, log = tmp_path / "k", tmp_path / "stderr.txt"
    child = start(cli(*LONG_PLAN, *WORKERS, "--out", str(out)), log)
    try:
        workers = wait_for_workers(child, log)
        (os.killpg if to_group else os.kill)(child.pid, stop)
        assert child.wait(timeout=60) == code
        err = log.read_text()
        assert "Traceback" not in err and "concurrent.futures" not in err, err
        assert err == f"trajectotree plan: {message}\n"
        assert wait_gone(workers) == [] and left_in_session(child.pid) == []
        assert not out.exists()  # stopped while planning: nothing written
    finally:
        kill_session(child)


# ---- the pool helper, forked and spawned: a script that makes a pool and waits -----------------------

POOL_SCRIPT = """
import sys, time
from trajectotree.planning.workers import kill_pool, process_pool

if __name__ == "__main__":
    pool = process_pool(2, sys.argv[1])
    futures = [pool.submit(time.sleep, 600) for _ in range(3)]  # two running, one queued
    try:
        print(*pool._processes, flush=True)  # the workers just started (spawned ones still starting)
        time.sleep(600)
    except KeyboardInterrupt:
        time.sleep(1.0)  # s, time for a worker that took the signal too to act on it (the CLI kills at once)
        print(*(pid for pid, p in pool._processes.items() if p.is_alive()), flush=True)
        kill_pool(pool)
        print("interrupted", file=sys.stderr)
        sys.exit(130)
"""


def ignores_sigint(pid: int) -> bool:
    """Whether `pid` ignores SIGINT (/proc's SigIgn mask): a pool worker past its initializer."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    ignored = int(next(line for line in status.splitlines() if line.startswith("SigIgn:")).split()[1], 16)
    return bool(ignored & 1 << (signal.SIGINT - 1))


def start_pool_script(start_method: str, log: Path) -> tuple[subprocess.Popen, list[int]]:
    """POOL_SCRIPT in a session of its own, and its two workers' pids."""
    with open(log, "w") as stderr:
        child = subprocess.Popen(
            [sys.executable, "-c", POOL_SCRIPT, start_method],
            start_new_session=True,
            preexec_fn=_as_from_a_shell,
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
        )
    workers = [int(p) for p in child.stdout.readline().split()]
    assert len(workers) == 2, log.read_text()
    return child, workers


@pytest.mark.parametrize("start_method", ["fork", "spawn"])  # keyframes' segments, a sweep's executions
def test_a_pools_workers_die_with_their_parent(start_method, tmp_path):
    log = tmp_path / "stderr.txt"
    child, workers = start_pool_script(start_method, log)
    try:
        deadline = time.monotonic() + 60
        while not all(ignores_sigint(p) for p in workers):  # each past its initializer, tied to the parent
            assert time.monotonic() < deadline, "the workers never ran their initializer"
            time.sleep(0.05)
        child.kill()
        child.wait(timeout=30)
        assert wait_gone(workers) == [], f"of the workers {workers}, left running"
        assert left_in_session(child.pid) == []
    finally:
        child.stdout.close()
        kill_session(child)


@pytest.mark.parametrize("start_method", ["fork", "spawn"])
def test_ctrl_c_while_a_pools_workers_start_prints_no_worker_traceback(start_method, tmp_path):
    """Ctrl-C at once, while spawned workers are still starting their interpreters: their stop
    signals are blocked until they ignore SIGINT, and the parent alone decides (it waits a second
    here, as a busy parent might: a worker that took the signal would print a traceback by then)."""
    log = tmp_path / "stderr.txt"
    child, workers = start_pool_script(start_method, log)
    try:
        os.killpg(child.pid, signal.SIGINT)
        assert child.wait(timeout=30) == 130
        assert log.read_text() == "interrupted\n"
        assert sorted(int(p) for p in child.stdout.readline().split()) == sorted(workers)  # alive until killed
        assert wait_gone(workers) == []
    finally:
        child.stdout.close()
        kill_session(child)


def test_a_worker_whose_parent_died_before_its_initializer_exits():
    """The race PR_SET_PDEATHSIG cannot close: the parent gone before the worker asked (told a
    parent pid that is not its parent's, the worker ends at once; told its parent's, it goes on)."""
    exit_codes = {}
    for parent in (os.getpid(), os.getpid() + 10**6):
        process = multiprocessing.get_context("fork").Process(target=_start_worker, args=(parent,))
        process.start()
        process.join(timeout=30)
        exit_codes[parent] = process.exitcode
    assert exit_codes == {os.getpid(): 0, os.getpid() + 10**6: 1}
