"""The plan-constrained program's structure (eqs. 11-19) from a hand-made contact plan."""

import dataclasses

import numpy as np
import pytest

from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program, general_spec
from trajectotree.cito.transition import check_plan, transition_spec
from trajectotree.config import CitoConfig, ConfigError, SceneConfig
from trajectotree.contact_plan import ContactNode, ContactPlan
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.plant import build_scene

CONFIG = CitoConfig(knots_per_segment=4)


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def body(scene, config: CitoConfig, mu: float = 0.5) -> BodyParams:
    return BodyParams(scene, config.sdf_sharpness, mu=mu)


def node(theta, arclengths, switching):
    box = ConvexPolygon.box(0.20, 0.10)
    points = [box.point(s) for s in arclengths]
    return ContactNode(
        object_pose=np.array([0.0, 0.0, theta]),
        q=np.zeros(8),
        arclengths=np.array(arclengths),
        p_BC=np.array([p for p, _ in points]),
        n_B=np.array([n for _, n in points]),
        switching_finger=switching,
        closure_margin=0.1,
    )


@pytest.fixture
def plan():
    # Finger 2 moves in segment 0, nobody in segment 1.
    a = [0.5, 0.2, 0.27, 0.48]
    b = [0.5, 0.2, 0.25, 0.48]
    return ContactPlan(goal=0.2, success=True, nodes=(node(0.0, a, None), node(0.1, b, 2), node(0.2, b, None)))


def test_transition_spec_pins_fixed_fingers_and_frees_the_switching_one(plan):
    r = 0.01
    spec = transition_spec(plan, radius=r, config=CONFIG)
    M = CONFIG.knots_per_segment
    assert spec.num_knots == 2 * M + 1
    free = ~spec.pinned
    assert np.array_equal(np.argwhere(free), [[k, 2] for k in range(1, M)])  # interior of segment 0 only
    n0, n1 = plan.nodes[0], plan.nodes[1]
    np.testing.assert_allclose(spec.c_B[0, 2], n0.p_BC[2] + r * n0.n_B[2])  # old contact at the first knot
    np.testing.assert_allclose(spec.c_B[M, 2], n1.p_BC[2] + r * n1.n_B[2])  # new contact at the last
    np.testing.assert_allclose(spec.c_B[:, 0], np.tile(n0.p_BC[0] + r * n0.n_B[0], (2 * M + 1, 1)))
    assert list(spec.rest_knots) == [0, M, 2 * M]
    assert [len(g) for g in spec.goal_poses] == [1] * M + [2] + [1] * M  # shared knot: both goals
    np.testing.assert_allclose(spec.goal_poses[1][0], [0.0, 0.0, 0.1])
    np.testing.assert_allclose(spec.goal_poses[-1][0], [0.0, 0.0, 0.2])


def test_programs_have_the_expected_size(scene, plan):
    spec = transition_spec(plan, radius=scene.tip_radius, config=CONFIG)
    prog = build_program(CONFIG, spec, body(scene, CONFIG))
    K = spec.num_knots
    assert prog.prog.num_vars() == 53 * K
    assert len(prog.knot_bindings) == K
    # 11 body rows per knot, 4 per pinned finger, 6 per free finger.
    assert (
        sum(b.evaluator().num_constraints() for b in prog.knot_bindings)
        == 11 * K + 4 * spec.pinned.sum() + 6 * (~spec.pinned).sum()
    )
    general = general_spec(x0=[0, 0, 0], q0=np.zeros(8), object_path=plan.object_path, config=CONFIG)
    assert not general.pinned.any() and list(general.rest_knots) == [0, K - 1]


def test_friction_cones_use_the_planning_friction(scene, plan):
    """The linear cone rows are mu_plan lambda_n -/+ lambda_t >= 0 with body.mu, for every finger and knot."""
    spec = transition_spec(plan, radius=scene.tip_radius, config=CONFIG)
    program = build_program(CONFIG, spec, body(scene, CONFIG, mu=0.42))
    n = spec.num_knots * 4
    cones = [b for b in program.prog.linear_constraints() if b.evaluator().num_constraints() == 2 * n]
    assert len(cones) == 1
    A = cones[0].evaluator().GetDenseA()
    np.testing.assert_array_equal(A[:, :n], 0.42 * np.vstack([np.eye(n), np.eye(n)]))
    np.testing.assert_array_equal(A[:, n:], np.vstack([-np.eye(n), np.eye(n)]))
    assert [v.get_name() for v in cones[0].variables()[:1]] == [program.variables.lambda_n[0, 0].get_name()]


def test_check_plan_rejects_plans_of_another_box(scene, plan):
    check_plan(plan, scene)
    flat = build_scene(SceneConfig(box_height=0.08))  # top and bottom faces move
    with pytest.raises(ConfigError, match="off the boundary"):
        check_plan(plan, flat)
    moved = dataclasses.replace(
        plan, nodes=(dataclasses.replace(plan.nodes[0], object_pose=np.array([0.1, 0, 0])),) + plan.nodes[1:]
    )
    with pytest.raises(ConfigError, match="starts at pose"):
        check_plan(moved, scene)
    with pytest.raises(ConfigError, match="nodes"):
        check_plan(dataclasses.replace(plan, nodes=plan.nodes[:1]), scene)


def test_switch_clearance_lifts_the_switching_finger_mid_move(scene, plan):
    M, h = CONFIG.knots_per_segment, 0.01
    paper = dataclasses.replace(CONFIG, switch_clearance=0.0)
    assert not transition_spec(plan, radius=scene.tip_radius, config=paper).clearance.any()  # the paper's: none
    assert CitoConfig().switch_clearance == h  # the default lifts
    config = dataclasses.replace(CONFIG, switch_clearance=h)
    spec = transition_spec(plan, radius=scene.tip_radius, config=config)
    expected = np.zeros((spec.num_knots, 4))
    expected[: M + 1, 2] = h * np.sin(np.pi * np.arange(M + 1) / M)  # finger 2 switches in segment 0
    np.testing.assert_allclose(spec.clearance, expected, atol=1e-15)
    assert not spec.clearance[spec.pinned].any()  # not even sin(pi) * h at the arrival knot: it may push there
    program = build_program(config, spec, body(scene, config))
    for k, binding in enumerate(program.knot_bindings):
        lower = binding.evaluator().lower_bound()
        free_row = program.rows.row_start[k, 2]
        assert lower[free_row] == pytest.approx(expected[k, 2] if 0 < k < M else 0.0)
        assert np.count_nonzero(lower) == (1 if 0 < k < M else 0)
