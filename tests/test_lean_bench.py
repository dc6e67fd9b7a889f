"""scripts/bench_planning.py's phase timing (issue 35): the child process's rows split plan()'s
wall-clock time into phases that add up to it, and the parent prints both trees side by side."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"


def run(args: list[str], tmp_path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, *args], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_compare_prints_both_trees_whose_phases_add_up_to_the_wall_clock(tmp_path):
    # the same checkout as the other tree: the report names both and gives each its statistics; a
    # negative first goal reaches the child as a value, not an option
    rows = tmp_path / "rows.json"
    command = [str(SCRIPTS / "bench_planning.py"), "--compare", str(ROOT), "--goal-list=-0.3", "--cli-goals", "1"]
    done = run([*command, "--json", str(rows)], tmp_path)
    assert done.returncode == 0, done.stderr
    plan_lines = [line for line in done.stdout.splitlines() if line.startswith("trajectotree ")]
    assert [line.split()[1] for line in plan_lines] == ["this", "compare"]
    assert "`trajectotree plan` process" in done.stdout
    # each child's row (scripts/plan_timing.py) splits plan()'s wall clock into phases that add up to it
    for tree in json.loads(rows.read_text()).values():
        (row,) = tree["rows"]
        assert row["success"] and row["physics_passed"]
        phases = ("search_s", "first_round_s", "retries_s", "pool_s", "other_s")
        assert all(row[p] >= 0.0 for p in phases)
        assert sum(row[p] for p in phases) == pytest.approx(row["wall_s"], rel=1e-9)
        assert row["first_round_s"] > 0.0 and tree["start_up_s"][0] > 0.0
