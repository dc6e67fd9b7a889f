"""General CITO in space (cito.space_cito.SpaceCitoRows, planning.spatial.plan_space_cito) on fingerpro4: its knot rows'
analytic Jacobian against central differences within its declared sparsity, the cold start keeping every knot
row; `trajectotree plan --hand fingerpro4 --method cito` on a small goal writes a result with a reason or a plan
that passes the check redone from its files (slow); an unknown method exits 2 and writes nothing."""

import json

import numpy as np
import pytest
from conftest import jacobian_against_differences
from pydrake.math import RollPitchYaw

from trajectotree.cito.space_cito import SpaceCitoRows, cito_cold_start
from trajectotree.cito.space_hand import space_fingers
from trajectotree.cito.spatial import SPACE_DT
from trajectotree.cli import main
from trajectotree.config import Config, mu_plan
from trajectotree.planning.spatial import recheck_space_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import space_initial_grasp

SMALL_GOAL_RPY = (0.3, 0.2, 0.1)  # rad: 21 deg from the start, two segments' worth of knots (21)
SMALL_GOAL = RollPitchYaw(SMALL_GOAL_RPY).ToQuaternion().wxyz()  # [w, x, y, z]


class _Knots:
    """Knots first..stop-1 of the rows as one constraint (values, jacobian, sparsity), for the differences."""

    def __init__(self, rows: SpaceCitoRows, first: int, stop: int):
        self.part = rows.knots(first, stop)
        self.shape = (stop - first, rows.layout.width)

    def values(self, Z):
        return self.part.knot_values(Z.reshape(self.shape))[0].ravel()

    def jacobian(self, Z):
        values, J = self.part.knot_jacobians(Z.reshape(self.shape))
        K, R, W = J.shape
        full = np.zeros((K * R, K * W))
        for k in range(K):
            full[k * R : (k + 1) * R, k * W : (k + 1) * W] = J[k]
        return values.ravel(), full

    def sparsity(self):
        mask = self.part.knot_mask()
        K, (R, W) = self.shape[0], mask.shape
        return [(k * R + r, k * W + c) for k in range(K) for r, c in zip(*np.nonzero(mask))]


@pytest.fixture(scope="module")
def cold():
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    grasp = space_initial_grasp(scene, SMALL_GOAL, config.search, mu)
    assert grasp.success and len(grasp.nodes) == 1
    fingers = space_fingers(scene)
    spec, Z = cito_cold_start(scene, fingers, grasp.nodes[0], SMALL_GOAL, mu)
    return scene, fingers, spec, Z, mu


@pytest.mark.parametrize("links", [False, True])
def test_knot_jacobian_against_central_differences(cold, links):
    scene, fingers, spec, Z, mu = cold
    rows = SpaceCitoRows(scene, fingers, spec, mu, SPACE_DT, links)
    assert rows.K == 21
    lo, hi = rows.knot_bounds()
    values = rows.knot_values(Z)[0]
    no_links = slice(0, rows.link_row)  # the held start grasp keeps every row but links the slerp turns into the box
    assert np.all(values[:, no_links] >= lo[:, no_links] - 1e-9) and np.all(
        values[:, no_links] <= hi[:, no_links] + 1e-9
    )
    Z = Z + 1e-3 * np.random.default_rng(1).standard_normal(Z.shape)
    constraint = _Knots(rows, 3, 5)
    J, _, pattern = jacobian_against_differences(constraint, Z[3:5])
    assert not np.any(J[~pattern])  # every entry within the declared sparsity
    batch = rows.knot_jacobians(Z)[1][3:5]  # all knots at once, as the cache evaluates them, equal one by one
    assert np.array_equal(batch, rows.knots(3, 5).knot_jacobians(Z[3:5])[1])


# General CITO from the search's initial grasp without the stance margin's preference: 5 s to its result; from the
# margin's first root it took 50 s (a test of the method's outcome, not of that grasp)
NO_MARGIN = ["--config-text", "{search: {space_stance_margin: none}}"]


@pytest.mark.slow
def test_cito_in_space_returns_a_result_or_a_checked_plan(tmp_path, capsys):
    out = tmp_path / "cito"
    code = main(["plan", "--hand", "fingerpro4", "--goal-rpy", *map(str, SMALL_GOAL_RPY), "--method", "cito",
                 "--out", str(out), *NO_MARGIN])  # fmt: skip
    assert code == 0
    data = json.loads((out / "plan.json").read_text())
    assert data["method"] == "cito" and len(data["segments"]) == 1
    assert "cito in space" in capsys.readouterr().out
    if data["success"]:
        check = recheck_space_plan(out)
        assert check.passed, check.reason
    else:
        assert data["status"]  # the reason: IPOPT's status, the check's or the goal's
        if (out / "plan.npz").exists():
            assert recheck_space_plan(out).passed == data["physics_check"]["passed"]


def test_an_unknown_method_exits_2_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "never"
    argv = ["plan", "--hand", "fingerpro4", "--goal-rpy", "0.3", "0.2", "0.1", "--method", "citto", "--out", str(out)]
    assert main(argv) == 2
    assert "method = 'citto' is unknown; valid: trajectotree, cito, cito-warm" in capsys.readouterr().err
    assert not out.exists()
