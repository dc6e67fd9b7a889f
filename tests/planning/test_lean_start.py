"""A quick start (issue 35): the Python API keeps its segment workers between plan() calls made
from the main thread (a script planning many goals starts them once), those workers still die with
their parent, a plan from another thread keeps none, and `trajectotree plan` imports no other
command's machinery."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# Two segments of the default box (2 s of solves): enough to use two workers.
PLANS = """
import threading
from trajectotree.planning.planners import plan

CONFIG = {"search": {"num_nodes": 3}}


def worker_pids(result):
    return sorted({a["pid"] for s in result.segments for a in s["attempts"]})
"""


def run_script(body: str, tmp_path: Path, **kwargs) -> subprocess.Popen:
    script = tmp_path / "script.py"
    script.write_text(PLANS + textwrap.dedent(body))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, str(script)], env=env, cwd=tmp_path, stdout=subprocess.PIPE, text=True, **kwargs
    )


def alive(pid: int) -> bool:
    """pid runs and is no zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def wait_gone(pids, timeout_s: float = 30.0) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


@pytest.mark.slow
def test_plan_keeps_its_workers_between_calls_and_they_die_with_it(tmp_path):
    child = run_script(
        """
        import os, sys
        first = plan(goal=0.3, config=CONFIG, segment_workers=2)
        second = plan(goal=-0.3, config=CONFIG, segment_workers=2)
        assert first.success and second.success
        print(*worker_pids(first), *worker_pids(second), os.getpid(), flush=True)
        sys.stdin.read()  # held until the test kills this process
        """,
        tmp_path,
        stdin=subprocess.PIPE,
    )
    try:
        *pids, parent = [int(p) for p in child.stdout.readline().split()]
        assert len(pids) == 4 and pids[:2] == pids[2:] and parent not in pids  # the same two workers twice
        assert all(alive(p) for p in pids)  # kept while the parent lives
        child.send_signal(signal.SIGKILL)  # no clean-up of the parent runs
        child.wait(timeout=30)
        assert wait_gone(pids[:2]) == []
    finally:
        child.kill()
        child.wait()
        child.stdout.close()
        child.stdin.close()


@pytest.mark.slow
def test_a_plan_from_another_thread_keeps_no_workers(tmp_path):
    child = run_script(
        """
        got = []
        for _ in range(2):
            thread = threading.Thread(target=lambda: got.append(plan(goal=0.3, config=CONFIG, segment_workers=2)))
            thread.start()
            thread.join()
        assert all(r.success for r in got)
        print(*worker_pids(got[0]), *worker_pids(got[1]), flush=True)
        """,
        tmp_path,
    )
    try:
        pids = [int(p) for p in child.stdout.readline().split()]
        assert child.wait(timeout=120) == 0
        assert len(pids) == 4 and not set(pids[:2]) & set(pids[2:])  # a pool per call, gone with it
        assert wait_gone(pids) == []
    finally:
        child.kill()
        child.wait()
        child.stdout.close()


@pytest.mark.slow
def test_plan_imports_no_other_commands_machinery(tmp_path):
    code = (
        "import atexit, sys\n"
        "atexit.register(lambda: print(' '.join(sorted(sys.modules))))\n"
        "from trajectotree.cli import main\n"
        f"sys.exit(main(['plan', '--goal', '0.3', '--segments', '2', '--out', {str(tmp_path / 'p')!r}]))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    modules = set(done.stdout.split())
    assert "trajectotree.planning.planners" in modules and "trajectotree.cli.plan_cmd" in modules  # can fail
    other = {f"trajectotree.cli.{c}_cmd" for c in ("demo", "scene", "search", "simulate", "state", "sweep", "report")}
    heavy = {"matplotlib", "dask", "distributed", "tqdm", "trajectotree.experiments", "trajectotree.figures"}
    assert not modules & (other | heavy)
    assert (tmp_path / "p" / "plan.json").exists()
