"""The keyframes formulation in space (cito.spatial, planning.spatial) on fingerpro4: the segment rows' Jacobian
(complex steps and the analytic lambda columns) against central differences, the fingers' closed-form gravity
torques against the plant, the time law the trapezoidal rule integrates exactly; bad input. A plan by
`trajectotree plan --hand fingerpro4` rechecked from its files: tests/planning/test_space_axis_aligned.py."""

import json
import math

import numpy as np
import pytest
from conftest import jacobian_against_differences

from trajectotree.cito import spatial as sp
from trajectotree.cito.space_hand import space_fingers
from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, mu_plan
from trajectotree.planning.spatial import recheck_space_plan
from trajectotree.scene.spatial import build_space_scene

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="module")
def setting(quarter_turn):
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    plan = quarter_turn(config.search)  # conftest's: searched once per process
    assert plan.success
    return scene, space_fingers(scene), plan, mu


def test_gravity_torques_match_the_plant(setting):
    scene, fingers, _, _ = setting
    q = np.random.default_rng(0).uniform(-0.3, 0.9, (4, 3))
    mine = np.array([f.torques(q[i], np.zeros(3), np.zeros(3), scene.gravity)[1] for i, f in enumerate(fingers)])
    assert np.allclose(mine, scene.gravity_torques(q), atol=1e-12)
    assert np.abs(mine).max() > 0.05  # N m: the fingers' weight binds


def test_time_law_keeps_the_rule():
    s, rate = sp.time_law(10)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0) and rate[0] == pytest.approx(0.0, abs=1e-15) == rate[-1]
    assert np.allclose(np.diff(s), 0.5 * (rate[1:] + rate[:-1]))


@pytest.mark.parametrize("segment", [0, 1])  # a segment without a switch, one with
def test_jacobian_against_central_differences(setting, segment):
    scene, fingers, plan, mu = setting
    spec = sp.segment_spec(scene, fingers, plan.nodes[segment], plan.nodes[segment + 1])
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, 4, sp.SPACE_DT)
    constraint = sp.SegmentConstraint(rows)
    Z = sp.guess(rows)
    lo, hi = rows.knot_bounds()
    values = rows.knot_values(Z)[0]
    assert np.all(values >= lo - 1e-9) and np.all(values <= hi + 1e-9)  # the guess keeps the knot rows
    Z = Z + 1e-3 * np.random.default_rng(1).standard_normal(Z.shape)
    J, numeric, pattern = jacobian_against_differences(constraint, Z)
    assert not np.any(J[~pattern])  # every entry within the declared sparsity


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hand", "fingerpro4", "--goal-quat", "0", "0", "0", "0"], "--goal-quat = [0.0, 0.0, 0.0, 0.0] has norm 0"),
        (["--hand", "fingerpro4", "--goal-quat", "1", "0", "nan", "0"], "--goal-quat[2] = nan is not a finite number"),
        (["--goal-quat", "1", "0", "0", "0"], "takes a hand in space; the hand 'planar_hand' is planar"),
    ],
)
def test_bad_goals_exit_2_and_write_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "never"
    assert main(["plan", *argv, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_plan_whose_arrays_do_not_fit_is_named(tmp_path):
    """A 3D plan.npz whose arrays disagree in shape: a ConfigError naming the file and the array (exit 2)."""
    K = 3
    arrays = {
        "t": np.arange(K, dtype=float),
        "x": np.tile([1.0, 0, 0, 0, 0, 0, 0], (K, 1)),
        "v": np.zeros((K, 6)),
        "q": np.zeros((K, 12)),
        "tau": np.zeros((K, 12)),
        "f_W": np.zeros((K, 4, 3)),
        "p_W_C": np.zeros((K, 4, 2)),  # planar points in a plan in space
        "p_W_tip": np.zeros((K, 4, 3)),
        "p_W_links": np.zeros((K, 4, 3, 2, 3)),
    }
    np.savez(tmp_path / "plan.npz", **arrays)
    obj = {"size": [0.065] * 3, "mass": 0.094, "inertia": np.eye(3).tolist(), "gravity": 9.81}
    (tmp_path / "plan.json").write_text(json.dumps({"object": {**obj, "tip_radius": 0.01, "link_radii": [0.01] * 3}}))
    with pytest.raises(
        ConfigError,
        match=r"plan.npz p_W_C has shape \(3, 4, 2\), expected \(KxFx3\) with K = 3 >= 2 knots, F = 4 fingers",
    ):
        recheck_space_plan(tmp_path)
