"""`trajectotree simulate PLAN_DIR` of a plan in space (cli.space_simulate, execution.space_run): a 34 deg turn about
a horizontal axis planned and executed open loop without a drop, sim.npz and sim.json in their 3D shapes; a hand of
the other kind than the plan's, an option space does not take yet and arrays of another cube exit 2 naming the
mismatch, writing nothing."""

import json
import shutil

import numpy as np
import pytest

from trajectotree.cli import main


def _copy(folder, tmp_path):
    target = tmp_path / "plan"
    shutil.copytree(folder, target)
    return target


@pytest.mark.slow
def test_a_plan_in_space_executes_without_a_drop(space_plan, tmp_path, capsys):
    plan = _copy(space_plan, tmp_path)
    assert main(["simulate", str(plan)]) == 0
    out = capsys.readouterr().out
    assert "held" in out and "sim.json" in out
    summary = json.loads((plan / "sim.json").read_text())
    assert summary["kind"] == "space" and summary["executor"] == "grasp" and summary["plan_success"]
    assert not summary["dropped"]
    assert summary["final_orientation_error_rad"] < np.radians(3.0)
    assert summary["final_position_error_m"] < 3e-3
    with np.load(plan / "plan.npz") as p, np.load(plan / "sim.npz") as s:
        K, F = len(s["t"]), p["f_W"].shape[1]
        assert s["x"].shape == s["x_plan"].shape == (K, 7)
        assert s["q"].shape == (K, p["q"].shape[1]) and s["f_W"].shape == (K, F, 3)
        assert s["t"][-1] == pytest.approx(p["t"][-1] + 0.5)  # the plan, then sim.settle_time of hold
        np.testing.assert_allclose(s["x_plan"][-1], p["x"][-1], atol=1e-9)  # the plan's end, held
        # the fingers carry the cube at the end: their forces' sum is its weight
        np.testing.assert_allclose(s["f_W"][-1].sum(axis=0), [0.0, 0.0, 0.094 * 9.81], atol=0.05)


def _refused(argv, plan, capsys) -> str:
    before = sorted(p.name for p in plan.iterdir())
    assert main(argv) == 2
    assert sorted(p.name for p in plan.iterdir()) == before  # nothing written, no lock left
    return capsys.readouterr().err


@pytest.mark.slow  # the shared plan: ~6 s
def test_a_plan_in_space_with_a_planar_hand_exits_2(space_plan, capsys):
    err = _refused(["simulate", str(space_plan), "--hand", "planar_hand"], space_plan, capsys)
    assert "--hand 'planar_hand' is a planar hand" in err and "holds a plan in space" in err


def test_a_planar_plan_with_a_hand_in_space_exits_2(tiny_plan, capsys):
    err = _refused(["simulate", str(tiny_plan), "--hand", "fingerpro4"], tiny_plan, capsys)
    assert "--hand 'fingerpro4' is a hand in space" in err and "holds a planar plan" in err


@pytest.mark.slow  # the shared plan: ~6 s
def test_arrays_of_another_cube_exit_2(space_plan, tmp_path, capsys):
    """plan.json beside the arrays of a plan of a 7.5 cm cube (its contacts moved 5 mm out): refused, naming plan.npz,
    the distance and the cube."""
    plan = _copy(space_plan, tmp_path)
    with np.load(plan / "plan.npz") as npz:
        arrays = {name: npz[name] for name in npz.files}
    x = arrays["x"]
    arrays["p_W_C"] = x[:, None, 4:] + (arrays["p_W_C"] - x[:, None, 4:]) * (0.0375 / 0.0325)
    np.savez(plan / "plan.npz", **arrays)
    err = _refused(["simulate", str(plan)], plan, capsys)
    assert "plan.npz" in err and "mm off the 65 x 65 x 65 mm cube plan.json names" in err
