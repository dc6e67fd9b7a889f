"""The public API of `trajectotree` and the examples/ scripts, run as a user would."""

import subprocess
import sys
from pathlib import Path

import pytest

import trajectotree

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_every_public_name_resolves_and_is_documented():
    for name in trajectotree.__all__:
        value = getattr(trajectotree, name)
        if callable(value):
            assert value.__doc__, name
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        trajectotree.nope  # noqa: B018


def test_importing_the_package_and_its_values_loads_no_drake():
    code = "import sys, trajectotree, trajectotree.results, trajectotree.config; print('pydrake' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


@pytest.mark.slow
def test_plan_and_simulate_example_runs(tmp_path):
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "plan_and_simulate.py")], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("Success: 10 nodes")
    assert lines[1] == "physics check passed: True"
    assert lines[2].startswith("dropped: False")
    assert (tmp_path / "playback.html").stat().st_size > 10_000
    assert {p.name for p in (tmp_path / "quarter_turn").iterdir()} == {"plan.json", "plan.npz"}
