"""The segment program in space (cito.spatial) as IPOPT receives it: the initial guess it starts from is the
program's guess knot by knot (Drake orders a matrix of variables column-major), the analytic Jacobian in its
declared sparsity against central differences at a perturbed guess (with the link rows too), the switching
finger's gap row on its lifted knots only, the end knots' pyramids the search's, one segment solved, and one
whose link went through the box solved again with the link rows."""

import math

import numpy as np
import pytest
from conftest import jacobian_against_differences
from pydrake.solvers import IpoptSolver
from scipy.spatial.transform import Rotation

from trajectotree.cito import spatial as sp
from trajectotree.cito.space_hand import space_fingers
from trajectotree.config import Config, mu_plan, with_values
from trajectotree.geometry import box_signed_distances, quaternion_matrices, segment_box_distances, segment_box_nearest
from trajectotree.results import LINK_PENETRATION_TOL
from trajectotree.scene.spatial import build_space_scene
from trajectotree.scene.statics import pyramid_edges
from trajectotree.search.space_tree import find_space_contact_plan

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])


@pytest.fixture(scope="module")
def setting(quarter_turn):
    # the segments below (seed 0's goals 11 and 28) are those of the search without the stance margin's preference
    config = with_values(Config(), {"search.space_stance_margin": "none"})
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    plan = quarter_turn(config.search)  # conftest's: searched once per process
    assert plan.success
    return scene, space_fingers(scene), plan, mu, config


def _switching_segment(plan) -> int:
    return next(s for s in range(len(plan.nodes) - 1) if plan.nodes[s + 1].switching_finger is not None)


def test_ipopt_starts_from_the_guess_knot_by_knot(setting):
    scene, fingers, plan, mu, _ = setting
    s = _switching_segment(plan)
    program = sp.build_space_segment(
        scene, fingers, sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1]), mu
    )
    guess = sp.guess(program.rows)
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


@pytest.mark.parametrize(
    "rotated, links", [(False, False), (True, False), pytest.param(True, True, marks=pytest.mark.slow)]
)
def test_analytic_jacobian_in_its_sparsity(setting, rotated, links):
    """At the full segment's knots, a perturbed guess whose corrections phi are far from zero (rotated: the
    right Jacobian's higher terms) and whose switching finger is off the box (the clearance row's entries),
    with the link rows or not."""
    scene, fingers, plan, mu, _ = setting
    s = _switching_segment(plan)
    spec = sp.segment_spec(scene, fingers, plan.nodes[s], plan.nodes[s + 1])
    rows = sp.SpaceSegmentRows(scene, fingers, spec, mu, sp.SPACE_INTERVALS, sp.SPACE_DT, links)
    constraint = sp.SegmentConstraint(rows)
    rng = np.random.default_rng(2)
    Z = sp.guess(rows) + 1e-3 * rng.standard_normal((rows.K, rows.layout.width))
    if rotated:
        Z[:, rows.layout.slice("phi")] += rng.uniform(-0.25, 0.25, (rows.K, 3))
    assert np.any(rows.knot_values(Z)[0][:, rows.clearance_row] > 0)  # the clearance row is live
    J, numeric, pattern = jacobian_against_differences(constraint, Z)
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


def test_the_nearest_point_of_a_segment_has_its_least_distance():
    rng = np.random.default_rng(3)
    half = np.array([0.0325, 0.0325, 0.0325])
    a, b = rng.uniform(-0.1, 0.1, (200, 3)), rng.uniform(-0.1, 0.1, (200, 3))
    t = segment_box_nearest(half, a, b)
    assert np.all((t >= 0) & (t <= 1))
    at = box_signed_distances(half, a + t[:, None] * (b - a))
    assert np.allclose(at, segment_box_distances(half, a, b), atol=1e-12)
    samples = box_signed_distances(half, a[:, None] + np.linspace(0, 1, 101)[:, None] * (b - a)[:, None])
    assert np.all(at <= samples.min(axis=1) + 1e-12)


@pytest.mark.slow
def test_a_link_through_the_box_gets_the_link_rows(setting):
    """Seed 0's goal 11, segment 5: without link rows a link ends 9 mm inside the box (the physics check would
    refuse the plan); solved again with them, no capsule is more than 1 mm inside, by the plant's kinematics."""
    scene, fingers, _, mu, config = setting
    goal = Rotation.random(30, random_state=0).as_quat(scalar_first=True)[11]
    plan = find_space_contact_plan(scene, goal, config.search, mu)
    spec = sp.segment_spec(scene, fingers, plan.nodes[5], plan.nodes[6])
    plain = sp.build_space_segment(scene, fingers, spec, mu)
    first = IpoptSolver().Solve(plain.prog, None, sp.ipopt_options(config.cito))
    assert first.is_success() and sp.link_depth(plain.rows, first.GetSolution(plain.z)) > 5e-3
    result = sp.solve_space_segment(scene, fingers, spec, mu, config.cito)
    assert result.success and result.link_rows, result.status
    ends = scene.link_ends_W(result.x, result.q)  # (K, F, L, 2, 3)
    R = quaternion_matrices(result.x[:, :4])
    e_B = np.einsum("kji,kflej->kflei", R, ends - result.x[:, None, None, None, 4:])
    radii = np.array([c.radius for c in scene.link_capsules()[0]])
    depth = radii - segment_box_distances(scene.object.half, e_B[..., 0, :], e_B[..., 1, :])
    assert depth.max() <= LINK_PENETRATION_TOL


@pytest.fixture(scope="module")
def goal_28_segment_6(setting):
    """Seed 0's goal 28, segment 6 (no switch): its end node held within the motors by the search (0.388 N m)."""
    scene, fingers, _, mu, config = setting
    goal = Rotation.random(30, random_state=0).as_quat(scalar_first=True)[28]
    plan = find_space_contact_plan(scene, goal, config.search, mu)
    assert plan.nodes[7].switching_finger is None and plan.nodes[7].stance_torque <= scene.tau_max.min()
    return sp.segment_spec(scene, fingers, plan.nodes[6], plan.nodes[7])


def test_the_end_knots_pyramids_are_the_searchs(setting, goal_28_segment_6):
    """With its pyramids turned otherwise than the search's, the hold at the segment's last knot needed 0.402 N m
    (> 0.396) and IPOPT failed; now the guess (the holding LP at each knot) keeps every row, torques included."""
    scene, fingers, _, mu, _ = setting
    rows = sp.SpaceSegmentRows(scene, fingers, goal_28_segment_6, mu, sp.SPACE_INTERVALS, sp.SPACE_DT)
    values = rows.knot_values(sp.guess(rows))[0]
    lo, hi = rows.knot_bounds()
    assert np.all(values >= lo - 1e-9) and np.all(values <= hi + 1e-9)
    for k in (0, -1):  # the search's construction in W at the nodes' orientations
        n_W = rows.n_B[k] @ rows.N[k].T
        assert np.allclose(rows.edges_B[k] @ rows.N[k].T, pyramid_edges(n_W, mu, sp.PYRAMID_EDGES), atol=1e-14)


@pytest.mark.slow
def test_goal_28_segment_6_solves(setting, goal_28_segment_6):
    scene, fingers, _, mu, config = setting
    result = sp.solve_space_segment(scene, fingers, goal_28_segment_6, mu, config.cito)
    assert result.success, result.status
