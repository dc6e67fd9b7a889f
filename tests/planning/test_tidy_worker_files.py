"""A forked pool worker holds none of its parent's files (trajectotree.planning.workers): the hang
of tests/execution/test_playback_browser.py run in one process. Its browser's driver (a subprocess
reading its stdin, started before the replanned run) never exited when told to, because the kept
pool's segment workers, forked afterwards, still held its stdin's write end, and the workers lived
until the interpreter's exit, which waited for the driver. Real processes throughout."""

import os
import subprocess
import sys

import pytest

from trajectotree.planning.workers import process_pool

READER = "import sys; sys.stdin.read()"  # a subprocess that exits at the end of its stdin, as the driver
EXIT_WAIT_S = 30  # s, a bound on the reader's exit once its stdin is closed (it takes milliseconds)


def start_reader() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", READER], stdin=subprocess.PIPE)


def exits_once_told(reader: subprocess.Popen) -> bool:
    """Closes the reader's stdin: whether it then exits (bounded: before the fix it waited forever)."""
    reader.stdin.close()
    try:
        reader.wait(timeout=EXIT_WAIT_S)
    except subprocess.TimeoutExpired:
        return False
    return True


def descriptor_target(fd: int) -> str:
    return os.readlink(f"/proc/self/fd/{fd}")


def shut_down(pool) -> list:
    """Shuts `pool` down (waiting for its workers); those of its worker processes still alive after."""
    processes = list(pool._processes.values())  # ProcessPoolExecutor has no public list of them
    pool.shutdown()
    return [p.pid for p in processes if p.is_alive()]


@pytest.mark.parametrize("start_method", ["fork", "spawn"])
def test_a_subprocess_started_before_a_pool_exits_once_told(start_method):
    reader = start_reader()
    pool = process_pool(2, start_method)
    try:
        pids = {pool.submit(os.getpid).result() for _ in range(4)}  # the workers run, and keep running
        assert pids and os.getpid() not in pids
        assert exits_once_told(reader), "the pool's workers held the reader's stdin open"
        assert reader.returncode == 0
    finally:
        reader.kill()
        assert shut_down(pool) == []


def test_a_forked_worker_has_the_parents_pipe_as_dev_null_and_still_works():
    reader = start_reader()
    pool = process_pool(2, "fork")
    try:
        fd = reader.stdin.fileno()
        assert descriptor_target(fd).startswith("pipe:")
        assert pool.submit(descriptor_target, fd).result() == os.devnull
        assert pool.submit(sum, range(10)).result() == 45  # its own pipes (the pool's queues) kept
    finally:
        reader.kill()
        assert shut_down(pool) == []


@pytest.mark.slow  # a real plan on the kept pool (seconds)
def test_a_subprocess_started_before_a_plan_exits_once_told():
    """The browser file's case, without the browser: a plan from the main thread on the segment pool
    it keeps (forked after the subprocess started), then the subprocess told to stop."""
    from trajectotree.config import Config, with_values
    from trajectotree.planning.planners import plan

    reader = start_reader()
    try:
        result = plan(goal=0.3, config=with_values(Config(), {"search.num_nodes": 3}), segment_workers=2)
        assert result.success, result.status
        assert exits_once_told(reader), "the kept pool's segment workers held the reader's stdin open"
    finally:
        reader.kill()
