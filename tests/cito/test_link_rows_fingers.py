"""LinkRows of a finger subset (issue 35 item 1): the rows of the named fingers only, equal to every
finger's rows at those fingers' positions, values, Jacobians and sparsity alike."""

import numpy as np
import pytest

from trajectotree.cito.knot import BodyParams
from trajectotree.cito.links import LinkRows
from trajectotree.config import Config
from trajectotree.scene.plant import build_scene


@pytest.fixture(scope="module")
def body():
    config = Config()
    return BodyParams(build_scene(config.scene), config.cito.sdf_sharpness, mu=0.5)


@pytest.mark.parametrize("fingers", [(1,), (3, 1), (0, 1, 2, 3)])
def test_a_subset_keeps_the_named_fingers_rows_of_the_whole(body, fingers):
    whole, part = LinkRows(body, 4), LinkRows(body, 4, fingers)
    P, V = whole.points.per_finger, len(body.shape.vertices)
    kept = sorted(fingers)
    rows = [i * P + j for i in kept for j in range(P)] + [4 * P + i * V + j for i in kept for j in range(V)]
    assert part.num_rows[0] == len(rows) == len(fingers) * (P + V)
    Z = np.random.default_rng(0).normal(scale=0.4, size=(4, whole.link_size))
    values, jacobians = whole.evaluate(Z, True)
    sub_values, sub_jacobians = part.evaluate(Z, True)
    np.testing.assert_array_equal(sub_values, values[:, rows])
    np.testing.assert_array_equal(sub_jacobians, jacobians[:, rows])
    np.testing.assert_allclose(part.values_one(Z[2]), sub_values[2], rtol=0, atol=1e-15)
    nonzero = {(int(r), int(c)) for r, c in zip(*np.nonzero(np.abs(sub_jacobians).max(axis=0)))}
    pattern = set(part.sparsity())
    assert nonzero <= pattern
    assert pattern == {(rows.index(r), c) for r, c in whole.sparsity() if r in rows}


def test_the_other_fingers_joints_are_outside_a_subsets_pattern(body):
    part = LinkRows(body, 1, (2,))
    columns = {c for _, c in part.sparsity()}
    others = {int(c) for i in (0, 1, 3) for c in part.col_q[i]}
    assert columns & others == set() and set(map(int, part.col_q[2])) <= columns
