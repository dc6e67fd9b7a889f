"""The sweep: goals from a seed, trials in child processes (local or Dask), the resumable store."""

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError
from trajectotree.sweep import (MANIFEST_FILE, ROWS_FILE, TRIALS_DIR, SweepSpec, prepare_dir, read_rows, run_sweep,
                                sample_goals)

# Small settings: 2 goals within +-0.3 rad, 2 transition segments.
SMALL = ["--goals", "2", "--seed", "0", "--max-goal", "0.3", "--segments", "2", "--no-progress"]


def small_spec(**changes) -> SweepSpec:
    config = Config()
    config = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    return SweepSpec(**{"goals": 2, "seed": 0, "methods": ("trajectotree",), "config": config, "max_goal": 0.3,
                        **changes})


def test_same_seed_gives_same_goals_in_range():
    a, b = sample_goals(60, 0), sample_goals(60, 0)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(a) <= math.pi) and a.std() > 1.0  # spread over [-pi, pi]
    assert not np.array_equal(a, sample_goals(60, 1))
    spec = SweepSpec(goals=60, seed=0)
    np.testing.assert_array_equal(spec.goal_values(), a)
    keys = [t.key for t in spec.tasks()]
    assert len(keys) == len(set(keys)) == 180 and keys[:3] == ["0000_trajectotree", "0000_cito", "0000_cito-warm"]


@pytest.mark.parametrize("args, message", [
    (["--goals", "0"], "--goals = 0"),
    (["--workers", "-1"], "--workers = -1"),
    (["--methods", "trajectotree", "rrt"], "unknown method 'rrt'"),
    (["--time-limit", "0"], "--time-limit = 0"),
    (["--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "1"], "cannot reach the Dask scheduler"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "sweep"
    assert main(["sweep", "--out", str(out), "--goals", "2", "--no-progress"] + args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_rerun_with_different_arguments_is_an_error(tmp_path, capsys):
    out = tmp_path / "sweep"
    prepare_dir(out, small_spec())
    manifest = (out / MANIFEST_FILE).read_bytes()
    assert main(["sweep", "--out", str(out), *SMALL, "--methods", "trajectotree", "cito"]) == 2
    err = capsys.readouterr().err
    assert "different arguments" in err and "methods" in err
    assert (out / MANIFEST_FILE).read_bytes() == manifest
    with pytest.raises(ConfigError, match="non-empty directory"):
        run_sweep(small_spec(), tmp_path, progress=False)  # a directory that is not a sweep
