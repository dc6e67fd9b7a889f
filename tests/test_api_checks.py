"""The Python API checks what the CLI checks, by the same functions (issue "Faults a user hit",
item 10): tt.plan takes a config as a path or a mapping and a start as a mapping or a path, refuses
an object the hand cannot hold before the search, and run_simulation refuses a playback it cannot
write before the run. Real plans throughout (tests/conftest.py's tiny_plan for a start and a run)."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY_PLAN

import trajectotree as tt
from trajectotree.cli import main
from trajectotree.planning import planners
from trajectotree.planning.request import as_config, as_start

PAPER_YAML = Path(__file__).resolve().parents[1] / "configs" / "paper.yaml"
ONE_SEGMENT = {"search": {"num_nodes": 2}}  # the cheapest plan: one transition segment
HEAVY = {"scene": {"box_mass": 10.0}, **ONE_SEGMENT}


def test_config_may_be_a_path_or_a_mapping(tmp_path):
    path = tmp_path / "one_segment.yaml"
    path.write_text("search:\n  num_nodes: 2\n")
    expected = tt.load_config(path)
    assert as_config(str(path)) == as_config(path) == as_config(ONE_SEGMENT) == expected
    assert as_config(None) == tt.Config() and as_config(expected) is expected
    with pytest.raises(tt.ConfigError, match=r"^config = 3 is of type int; give a Config, the path"):
        as_config(3)
    with pytest.raises(tt.ConfigError, match=r"does not exist"):
        tt.plan(goal=0.1, config=str(tmp_path / "missing.yaml"))
    result = tt.plan(goal=0.1, config=str(path))
    assert result.success and result.config.search.num_nodes == 2


def test_plan_takes_the_papers_config_file_by_its_path(tmp_path):
    assert as_config(str(PAPER_YAML)) == as_config(PAPER_YAML) == tt.load_config(PAPER_YAML)
    # the paper's formulation (one joint program) over one segment, from a file: the nine segments of the
    # paper's goals take minutes on 2 busy cores
    paper = tt.load_config(PAPER_YAML)
    path = tmp_path / "paper_one_segment.yaml"
    tt.save_config(dataclasses.replace(paper, search=dataclasses.replace(paper.search, num_nodes=2)), path)
    result = tt.plan(goal=0.1, config=str(path))
    assert result.converged and result.config.cito.formulation == "joint"
    assert result.config.search.friction_safety == paper.search.friction_safety == 1.0


def first_knot(plan_dir: Path) -> dict:
    """start.json's mapping of a plan's first knot: the object at rest in the plan's initial grasp."""
    with np.load(plan_dir / "plan.npz") as arrays:
        return {"object_pose": arrays["x"][0].tolist(), "q": arrays["q"][0].tolist()}


def test_start_may_be_a_mapping_or_a_path(tiny_plan, tmp_path):
    start = first_knot(tiny_plan)
    assert as_start(start) == tt.StartState(object_pose=tuple(start["object_pose"]), q=tuple(start["q"]))
    path = tmp_path / "start.json"
    path.write_text(json.dumps(start))
    assert as_start(path) == as_start(str(path)) == as_start(start)
    with pytest.raises(tt.ConfigError, match=r"^start '.*missing.json': no such file$"):
        as_start(tmp_path / "missing.json")
    with pytest.raises(tt.ConfigError, match=r"^start = \(0, 0\) is of type tuple; give a StartState"):
        as_start((0, 0))
    with pytest.raises(tt.ConfigError, match=r"^start: missing 'q'$"):
        tt.plan(goal=0.1, start={"object_pose": [0, 0, 0]})
    result = tt.plan(goal=0.1, start=start, config=ONE_SEGMENT)
    assert result.success
    np.testing.assert_allclose(result.trajectory.q[0], start["q"])  # CITO's first knot is the start


def test_plan_refuses_an_object_the_hand_cannot_hold_before_the_search(monkeypatch):
    def search(*args, **kwargs):
        raise AssertionError("the search ran")

    monkeypatch.setattr(planners, "find_contact_plan", search)
    with pytest.raises(tt.ConfigError) as refused:
        tt.plan(goal=0.1, config=HEAVY)
    message = str(refused.value)
    assert message.startswith("scene.box_mass = 10.0 kg is more than the hand can hold: the strongest of the ")
    assert "valid range: [0.001, " in message and message.endswith("] kg") and "\n" not in message


def test_the_cli_refuses_the_heavy_object_with_the_apis_words(tmp_path, capsys):
    with pytest.raises(tt.ConfigError) as refused:
        tt.plan(goal=0.1, config=HEAVY)
    capsys.readouterr()
    assert main(["plan", *TINY_PLAN, "--mass", "10", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err == f"trajectotree plan: error: {refused.value.as_option('--mass')}\n"
    assert err.startswith("trajectotree plan: error: --mass (scene.box_mass) = 10.0 kg is more than the hand can hold")
    assert list(tmp_path.iterdir()) == []


def test_run_simulation_refuses_a_playback_it_cannot_write_before_the_run(tiny_plan, tmp_path, monkeypatch):
    from trajectotree.execution import run

    def simulate(*args, **kwargs):
        raise AssertionError("the simulation ran")

    monkeypatch.setattr(run, "simulate_reference", simulate)
    plan = tt.load_plan(tiny_plan)
    refusals = {
        "/proc/playback.html": "html_path '/proc/playback.html' cannot be written: no file can be created in '/proc'",
        str(tmp_path / "no" / "run.html"): f"html_path {str(tmp_path / 'no' / 'run.html')!r}: the folder",
        str(tmp_path / "run.txt"): f"html_path {str(tmp_path / 'run.txt')!r}: the file name must end in .html or .htm",
    }
    for path, message in refusals.items():
        with pytest.raises(tt.ConfigError) as refused:
            tt.run_simulation(plan=plan, html_path=path)
        assert str(refused.value).startswith(message), str(refused.value)
    with pytest.raises(tt.ConfigError, match=r"^gif_path '.*run.png': the file name must end in .gif$"):
        tt.run_simulation(plan=plan, gif_path=tmp_path / "run.png")
    assert list(tmp_path.iterdir()) == []
