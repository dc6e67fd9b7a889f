"""The joint formulation's finger rows (fix2b): the one program over several segments pins its
middle and last knots to the search's nodes without fixing them, so its finger rows admit those
nodes' joints, as a keyframes piece's rows admit its fixed end knots; and each knot's binding has the
values and Jacobian of finite differences on a joint program.

The case: tests/cito/test_cito_polygon.py's hand-made triangle plan for goal 0.3, whose last node
holds fingers 1 and 2 on one side 20 mm apart, fingertips (radius 10 mm) touching. Before the fix
the joint program kept them 1 mm apart at every knot, so finger 1 stopped 0.53 mm short of its
contact while pushing 0.703 N (the physics check failed; test_a_triangle_plan_is_physical[joint])."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff

from trajectotree.cito.fingers import FingerRows, near_pairs
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program, link_knots
from trajectotree.cito.transition import transition_spec
from trajectotree.config import CitoConfig, mu_plan
from trajectotree.scene.plant import build_scene

sys.path.insert(0, str(Path(__file__).parent))
import test_cito_polygon as polygon  # noqa: E402  (the sibling test's triangle plan)

JOINT = dataclasses.replace(CitoConfig(), formulation="joint")


@pytest.fixture(scope="module")
def joint_program():
    """The triangle plan's joint program with its finger rows, built as planners.plan builds it."""
    scene = build_scene(polygon.CONFIG.scene)
    plan = polygon.contact_plan.__wrapped__(scene)
    q_nodes = [node.q for node in plan.nodes]
    spec = transition_spec(plan, radius=scene.tip_radius, config=JOINT)
    spec = dataclasses.replace(
        spec, finger_pairs=near_pairs(scene.fingers, q_nodes, scene.tip_radius), finger_nodes=tuple(q_nodes)
    )
    body = BodyParams(scene, JOINT.sdf_sharpness, mu=mu_plan(polygon.CONFIG.scene, polygon.CONFIG.search))
    return build_program(JOINT, spec, body), FingerRows(body, spec.finger_pairs, spec.num_knots), np.array(q_nodes)


def test_the_joint_program_s_finger_rows_admit_every_node_of_the_plan(joint_program):
    program, rows, q_nodes = joint_program
    assert program.spec.finger_pairs == ((1, 2),) and program.spec.segment_length == 12
    knots = link_knots(program.spec)
    assert knots == list(range(1, 25))  # the last knot (node 2) free: only the search's node bounds it
    assert len(program.finger_bindings) == len(knots)
    at_last_node = rows.values_one(q_nodes[-1])
    assert at_last_node.min() < JOINT.link_clearance  # the case: node 2's fingertips closer than the rows' 1 mm
    for binding in program.finger_bindings:
        lower = binding.evaluator().lower_bound()
        for q in q_nodes:  # every node, put at any free knot, satisfies the rows
            assert np.all(rows.values_one(q) >= lower - 1e-12)


def test_the_finger_bindings_match_finite_differences_on_a_joint_program(joint_program):
    program, rows, q_nodes = joint_program
    rng = np.random.default_rng(0)
    for k, binding in zip(link_knots(program.spec), program.finger_bindings):
        evaluator = binding.evaluator()
        # the knot near the node it leads to, perturbed by 0.05 rad: rows of all kinds active
        z = q_nodes[(k + 11) // 12] + rng.normal(0.0, 0.05, 8)
        y = evaluator.Eval(InitializeAutoDiff(z)[:, 0])
        values, jacobian = ExtractValue(y)[:, 0], ExtractGradient(y)
        np.testing.assert_array_equal(values, evaluator.Eval(z))
        np.testing.assert_allclose(values, rows.values_one(z), rtol=0, atol=1e-15)
        h = 1e-7
        fd = np.stack([(evaluator.Eval(z + h * e) - evaluator.Eval(z - h * e)) / (2 * h) for e in np.eye(8)], axis=1)
        np.testing.assert_allclose(jacobian, fd, atol=1e-7)
        pattern = np.zeros(jacobian.shape, dtype=bool)
        pattern[tuple(np.array(evaluator.gradient_sparsity_pattern()).T)] = True
        assert not np.any(fd[~pattern])  # the declared sparsity covers every nonzero
        assert np.abs(jacobian).max() > 0.1  # m / rad: the rows do depend on the joints
