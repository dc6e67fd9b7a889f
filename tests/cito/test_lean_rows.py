"""The knot rows and the link rows as one constraint each over every knot (issue 35): the values
and AutoDiff gradients Drake gets from the batch binding are the rows' own, in the sparsity
pattern it declares, and the chain rule holds for an input gradient other than the identity."""

import dataclasses

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff

from trajectotree.cito.knot import BodyParams
from trajectotree.cito.links import LinkRows
from trajectotree.cito.program import build_program, link_knots
from trajectotree.cito.transition import piece_spec
from trajectotree.config import Config, mu_plan
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

CONFIG = Config()


@pytest.fixture(scope="module")
def program():
    scene = build_scene()
    plan = find_contact_plan(scene, 0.3, dataclasses.replace(CONFIG.search, num_nodes=3))
    body = BodyParams(scene, CONFIG.cito.sdf_sharpness, mu=mu_plan(CONFIG.scene, CONFIG.search))
    spec = piece_spec(plan, 0, 1, radius=scene.tip_radius, config=CONFIG.cito)
    return build_program(CONFIG.cito, spec, body)


def random_point(program, seed: int) -> np.ndarray:
    Z = program.variables.stacked()
    return np.random.default_rng(seed).uniform(-0.5, 0.5, Z.shape)


def batch_rows(program, Z: np.ndarray, links: bool):
    """(values, dense Jacobian) the rows give at Z, knot after knot, on the binding's variables."""
    if links:
        rows, knots = LinkRows(program.rows.body, program.spec.num_knots), link_knots(program.spec)
        blocks = np.concatenate([Z[:, :3], Z[:, program.rows.layout.block.slices["q"]]], axis=1)[knots]
        val, jac = rows.evaluate(blocks, True)
        return blocks.ravel(), val.ravel(), _block_diagonal(jac)
    val, jac = program.rows.evaluate(Z, True)
    n = program.rows.num_rows
    return (
        Z.ravel(),
        np.concatenate([val[k, : n[k]] for k in range(len(n))]),
        _block_diagonal([jac[k, : n[k]] for k in range(len(n))]),
    )


def _block_diagonal(blocks) -> np.ndarray:
    rows, cols = sum(b.shape[0] for b in blocks), sum(b.shape[1] for b in blocks)
    out, r, c = np.zeros((rows, cols)), 0, 0
    for b in blocks:
        out[r : r + b.shape[0], c : c + b.shape[1]] = b
        r, c = r + b.shape[0], c + b.shape[1]
    return out


@pytest.mark.parametrize("links", [False, True], ids=["knot rows", "link rows"])
def test_one_binding_gives_the_rows_values_and_jacobian(program, links):
    binding = program.link_binding if links else program.knot_binding
    evaluator = binding.evaluator()
    z, val, jac = batch_rows(program, random_point(program, 1), links)
    assert evaluator.num_vars() == z.size and evaluator.num_constraints() == val.size
    np.testing.assert_array_equal(evaluator.Eval(z), val)
    y = evaluator.Eval(InitializeAutoDiff(z)[:, 0])
    np.testing.assert_array_equal(ExtractValue(y)[:, 0], val)
    np.testing.assert_array_equal(ExtractGradient(y), jac)
    pattern = np.zeros(jac.shape, dtype=bool)
    pattern[tuple(np.array(evaluator.gradient_sparsity_pattern()).T)] = True
    assert not np.any(jac[~pattern])  # every nonzero is declared
    assert pattern.sum() < 0.2 * pattern.size  # and the pattern is sparse (block-diagonal)


@pytest.mark.parametrize("links", [False, True], ids=["knot rows", "link rows"])
def test_the_chain_rule_holds_for_any_input_gradient(program, links):
    evaluator = (program.link_binding if links else program.knot_binding).evaluator()
    z, val, jac = batch_rows(program, random_point(program, 2), links)
    G = np.random.default_rng(3).normal(size=(z.size, 5))
    y = evaluator.Eval(InitializeAutoDiff(z, G)[:, 0])
    np.testing.assert_array_equal(ExtractValue(y)[:, 0], val)
    np.testing.assert_allclose(ExtractGradient(y), jac @ G, rtol=1e-12, atol=1e-12)
