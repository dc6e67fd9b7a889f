"""The `trajectotree` process ends without the interpreter's teardown (trajectotree.cli.end_without_teardown,
issue 35) yet as Python's exit would: its output all there through a pipe, its exit handlers run, its threads
and segment workers ended, its exit codes and messages the same; and its garbage collector is paused for
`plan`'s start-up alone (console, resume_collector), never for a program that calls main(). Real processes
throughout."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

# A plan of several segments on two segment workers: the kept pool is started, and shut down at the exit.
POOLED_PLAN = ["plan", "--goal", "0.5", "--segment-workers", "2"]

# Exit handlers, a thread still running and output still buffered as end_without_teardown is called, and an
# object whose finalizer runs only in the interpreter's teardown (a module global is collected there).
ENDING = """
import atexit, sys, threading, time
from trajectotree.cli import end_without_teardown

class Torn:
    def __del__(self):
        print("torn down", flush=True)

torn = Torn()
atexit.register(print, "atexit ran")
threading.Thread(target=lambda: (time.sleep(0.2), print("thread ended"))).start()
print("buffered", end="")
end_without_teardown(3)
"""


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "trajectotree.cli", *args]


def session_processes(sid: int) -> list[int]:
    """The live processes (zombies excluded) of session `sid`: an orphaned worker keeps its session."""
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text() if entry.name.isdigit() else ""
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split() if stat else []
        if fields and int(fields[3]) == sid and fields[0] != "Z":
            pids.append(int(entry.name))
    return pids


def test_end_without_teardown_runs_what_exit_runs_first():
    done = subprocess.run([sys.executable, "-c", ENDING], capture_output=True, text=True, timeout=60)
    assert done.returncode == 3, done.stderr
    assert done.stdout.splitlines() == ["bufferedthread ended", "atexit ran"]  # no "torn down": no teardown
    assert done.stderr == ""


def test_plan_process_ends_with_its_output_and_workers(tmp_path):
    out = tmp_path / "plan"
    with subprocess.Popen(
        cli(*POOLED_PLAN, "--json", "--out", str(out)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    ) as child:
        stdout, stderr = child.communicate(timeout=120)
    assert child.returncode == 0, stderr
    assert session_processes(child.pid) == []  # the segment workers ended with it
    printed = json.loads(stdout)  # all of it through the pipe (flushed before the process ended)
    assert printed == json.loads((out / "plan.json").read_text())
    assert printed["success"] and len(printed["segments"]) >= 2
    assert sorted(p.name for p in out.iterdir()) == ["plan.json", "plan.npz"]
    with np.load(out / "plan.npz") as arrays:
        assert abs(arrays["x"][-1, 2] - 0.5) < 1e-6  # rad, the goal reached


def test_bad_input_still_exits_2_with_one_line(tmp_path):
    out = tmp_path / "plan"
    done = subprocess.run(
        cli("plan", "--goal", "0.5", "--segment-workers", "0", "--out", str(out)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.startswith("trajectotree plan: error: --segment-workers") and done.stderr.count("\n") == 1
    assert not out.exists()


# console() with `plan`, recording the collector's passes from its start to the planning's.
PAUSED = """
import gc, sys
import trajectotree.cli.plan_cmd as plan_cmd
from trajectotree.cli import console

passes = []
gc.callbacks.append(lambda phase, info: phase == "start" and passes.append(info["generation"]))
planning = plan_cmd.plan_into

def plan_into(*args):
    print(f"start-up passes {len(passes)}, enabled {gc.isenabled()}, frozen {gc.get_freeze_count() > 0}", flush=True)
    return planning(*args)

plan_cmd.plan_into = plan_into
sys.argv = ["trajectotree", "plan", "--goal", "0.1", "--segments", "1", "--out", sys.argv[1]]
console()
"""

# main() called by a program: the collector as the program has it.
CALLED = """
import gc, sys
from trajectotree.cli import main

code = main(["plan", "--goal", "0.1", "--segments", "1", "--out", sys.argv[1]])
print(f"code {code}, enabled {gc.isenabled()}, frozen {gc.get_freeze_count()}")
"""


def test_collector_paused_for_the_start_up_only(tmp_path):
    done = subprocess.run(
        [sys.executable, "-c", PAUSED, str(tmp_path / "p")], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.splitlines()[0] == "start-up passes 0, enabled True, frozen True"
    assert (tmp_path / "p" / "plan.npz").is_file()


def test_main_leaves_the_programs_collector_alone(tmp_path):
    done = subprocess.run(
        [sys.executable, "-c", CALLED, str(tmp_path / "p")], capture_output=True, text=True, timeout=120
    )
    assert done.stdout.splitlines()[-1] == "code 0, enabled True, frozen 0", done.stderr[-2000:]
