"""The segment program in space (cito.spatial) as IPOPT receives it: the initial guess it starts from is the
program's guess knot by knot (Drake orders a matrix of variables column-major), the analytic Jacobian in its
declared sparsity against central differences at a perturbed guess, and one segment solved from it."""

import math

import numpy as np
import pytest

from trajectotree.cito import spatial as sp
from trajectotree.config import Config, mu_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.tree import find_space_contact_plan

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="module")
def setting():
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    plan = find_space_contact_plan(scene, QUARTER_ABOUT_X, config.search, mu)
    assert plan.success
    return scene, sp.space_fingers(scene), plan, mu, config


def _switching_segment(plan) -> int:
    return next(s for s in range(len(plan.nodes) - 1) if plan.nodes[s + 1].switching_finger is not None)


def test_ipopt_starts_from_the_guess_knot_by_knot(setting):
    scene, fingers, plan, mu, _ = setting
    s = _switching_segment(plan)
    program = sp.build_space_segment(
        scene, fingers, sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1]), mu
    )
    guess = sp._guess(program.rows)
    assert np.array_equal(program.prog.GetInitialGuess(program.z), guess)
    # what IPOPT starts from: the program's initial guess in its decision variables' order
    start = program.prog.GetInitialGuess(program.prog.decision_variables())
    values = program.prog.EvalBinding(program.binding, start)
    lo, hi = program.binding.evaluator().lower_bound(), program.binding.evaluator().upper_bound()
    assert np.all(values >= lo - 1e-9) and np.all(values <= hi + 1e-9)


def test_the_gap_row_binds_only_the_lifted_knots(setting):
    """At the last knot the switching fingertip is pinned to its new contact, r off the face: a gap row there
    (sin(pi) is 1e-16, not 0) was active with the pin and its multiplier reached 7e3."""
    scene, fingers, plan, mu, _ = setting
    s = _switching_segment(plan)
    spec = sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1])
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, sp.SPACE_INTERVALS, sp.SPACE_DT)
    gap = rows.knot_bounds()[0][:, -1]
    lifted = ~rows.pinned[:, spec.switching]
    assert not lifted[0] and not lifted[-1] and lifted[1:-1].all()
    assert np.all(np.isneginf(gap[~lifted])) and np.all(gap[lifted] > (scene.tip_radius**2) * rows.clearance_scale)


@pytest.mark.parametrize("rotated", [False, True])
def test_analytic_jacobian_in_its_sparsity(setting, rotated):
    """At the full segment's knots, a perturbed guess whose corrections phi are far from zero (rotated: the
    right Jacobian's higher terms) and whose switching finger is off the box (the clearance row's entries)."""
    scene, fingers, plan, mu, _ = setting
    s = _switching_segment(plan)
    spec = sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1])
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, sp.SPACE_INTERVALS, sp.SPACE_DT)
    constraint = sp._SegmentConstraint(rows)
    rng = np.random.default_rng(2)
    Z = sp._guess(rows) + 1e-3 * rng.standard_normal((rows.K, rows.layout.width))
    if rotated:
        Z[:, rows.layout.slice("phi")] += rng.uniform(-0.25, 0.25, (rows.K, 3))
    assert np.any(rows.knot_values(Z)[0][:, -1] > 0)  # the clearance row is live
    _, J = constraint.jacobian(Z)
    step = 1e-6
    numeric = np.empty_like(J)
    for j in range(Z.size):
        d = np.zeros(Z.size)
        d[j] = step
        d = d.reshape(Z.shape)
        numeric[:, j] = (constraint.values(Z + d) - constraint.values(Z - d)) / (2 * step)
    assert np.abs(J - numeric).max() < 1e-6 * max(1.0, np.abs(J).max())
    pattern = np.zeros(J.shape, dtype=bool)
    pattern[tuple(np.array(constraint.sparsity()).T)] = True
    assert not np.any(numeric[~pattern])  # the declared sparsity holds every entry
    assert pattern.sum() < 0.3 * pattern.size  # and is sparse: a knot row meets few of its knot's variables


@pytest.mark.slow
def test_a_switching_segment_solves(setting):
    scene, fingers, plan, mu, config = setting
    s = _switching_segment(plan)
    spec = sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1])
    result = sp.solve_space_segment(scene, fingers, spec, mu, config.cito)
    assert result.success, result.status
    assert np.allclose(result.q[0], spec.q_a.ravel()) and np.allclose(result.q[-1], spec.q_b.ravel())
    assert np.abs(result.tau).max() <= scene.tau_max.max() + 1e-6
