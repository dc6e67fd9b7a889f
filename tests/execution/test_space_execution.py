"""The grasp controller in space (trajectotree.execution.space_control) and its Diagram (space_run) on fingerpro4:
its force QP against the statics of a cube held at face centres, the orientation error from quaternions, and a
static hold of the search's initial grasp for 2 s in the discrete plant."""

import dataclasses
import math

import numpy as np
import pytest

from trajectotree.config import Config, mu_plan
from trajectotree.execution.executor import control_friction
from trajectotree.execution.space_control import SpaceGraspController, SpaceGraspForceQp, SpaceReference
from trajectotree.execution.space_run import simulate_space
from trajectotree.geometry import BOX_FACE_NAMES, BOX_FACE_NORMALS, quaternion_error_W, quaternion_matrices, so3_exp
from trajectotree.scene.spatial import build_space_scene
from trajectotree.scene.statics import (
    cone_rows_3d,
    contact_torque_rows,
    edge_wrenches_W,
    grasp_matrix_3d_W,
    pyramid_edges,
    tangent_basis,
)
from trajectotree.search.space_tree import find_space_contact_plan
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

HALF = 0.0325  # m, the cube's half size
MASS, GRAVITY = 0.094, 9.81
WEIGHT = MASS * GRAVITY  # N


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def _solve_hold(normals, mu: float, lo: float, hi: float = 8.0) -> np.ndarray:
    """The QP's forces f_W (F, 3) on a cube held at the centres of the faces with outward `normals`, asked for the
    wrench that holds it against gravity, every normal force in [lo, hi], no plan forces and unbounded motors."""
    n_W = np.array(normals, dtype=float)
    F = len(n_W)
    r_W = HALF * n_W  # the face centres, from the cube's centre
    qp = SpaceGraspForceQp(mu, math.sqrt(3) * HALF, 1e6, num_fingers=F, num_joints=3)
    D = np.stack([-n_W, *tangent_basis(n_W)], axis=-1)
    torque = contact_torque_rows(np.zeros((F, 3, 3)), D, np.zeros((F, 3)), np.full((F, 3), np.inf))
    lam = qp.solve(
        grasp_matrix_3d_W(r_W, n_W),
        np.array([0.0, 0.0, WEIGHT, 0.0, 0.0, 0.0]),
        np.zeros((F, 3)),
        np.full(F, lo),
        np.full(F, hi),
        torque,
    )
    return np.einsum("fck,fk->fc", D, lam)


def test_qp_four_side_faces_share_the_weight_equally():
    """Four fingertips at the side faces' centres: statics with the least forces has each carry a quarter of the
    weight upward and push with the least normal force."""
    f = _solve_hold([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], mu=0.7, lo=1.0)
    np.testing.assert_allclose(f[:, 2], WEIGHT / 4, atol=1e-3)
    np.testing.assert_allclose(f[:, :2], [[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]], atol=1e-3)


def test_qp_three_fingers_carry_the_weight_where_statics_lets_them():
    """Fingertips at the centres of +x, -x and +y: the +y one's upward force would turn the cube about x, which
    nothing else can cancel, so the +-x fingers carry half the weight each, and share the +y push's reaction."""
    lo = 2.0
    f = _solve_hold([[1, 0, 0], [-1, 0, 0], [0, 1, 0]], mu=0.7, lo=lo)
    expected = [[-lo, lo / 2, WEIGHT / 2], [lo, lo / 2, WEIGHT / 2], [0.0, -lo, 0.0]]
    np.testing.assert_allclose(f, expected, atol=2e-3)


def test_qp_forces_stay_in_their_cones():
    """Asked for more than friction allows at the least squeeze, the QP squeezes harder: each force inside the
    pyramid inscribed in its cone, the weight still held."""
    mu = 0.3
    f = _solve_hold([[1, 0, 0], [-1, 0, 0]], mu=mu, lo=0.1)
    n_W = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    normal = -np.sum(f * n_W, axis=1)
    tangential = np.linalg.norm(f - (f * n_W).sum(axis=1, keepdims=True) * n_W, axis=1)
    assert np.all(tangential <= mu * normal + 1e-6)
    assert np.all(normal > WEIGHT / 2 / mu - 1e-3)  # at least what the circle allows: the pyramid needs more
    np.testing.assert_allclose(f.sum(axis=0), [0.0, 0.0, WEIGHT], atol=1e-3)


def test_cone_rows_3d_are_the_pyramid_of_its_edges():
    """Every edge of pyramid_edges lies on two facets of cone_rows_3d (the rows are 0 there) and inside the others."""
    mu, m = 0.56, 8
    n = np.array([[0.0, 0.0, 1.0]])
    t1, t2 = tangent_basis(n)
    edges = pyramid_edges(n, mu, m)[0]  # (m, 3) in W
    lam = np.column_stack([-edges @ n[0], edges @ t1[0], edges @ t2[0]])  # each edge as (lambda_n, 1, 2)
    rows = cone_rows_3d(mu, 1, m) @ lam.T  # (facets, edges)
    assert np.all(rows <= 1e-12)
    assert np.all(np.sum(np.abs(rows) < 1e-12, axis=0) == 2)


def test_orientation_error_turns_the_measured_onto_the_plan():
    """quaternion_error_W: exp([e]x) R = R_plan, for rotations either way of pi/2 and either quaternion sign."""
    rng = np.random.default_rng(0)
    for _ in range(5):
        q_plan, q = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 4)))
        e = quaternion_error_W(q_plan, q)
        np.testing.assert_allclose(so3_exp(e) @ quaternion_matrices(q), quaternion_matrices(q_plan), atol=1e-12)
        np.testing.assert_allclose(quaternion_error_W(-q_plan, q), e, atol=1e-12)
        assert np.linalg.norm(e) <= math.pi + 1e-12


def _initial_grasp_hold(scene, duration: float) -> SpaceReference:
    """The search's initial grasp for a small turn (node 0), held still with the forces of the search's statics
    (SpatialHoldingLp: the weight held within the motors, the fingers' own weight included, at the planning
    friction). The search without the stance margin's preference: the grasp the closed loop's push reflex was
    measured on (the margin's first root engages it 10 ms later)."""
    config = Config()
    config = dataclasses.replace(config, search=dataclasses.replace(config.search, space_stance_margin="none"))
    mu = mu_plan(config.scene, config.search)
    goal = np.array([math.cos(0.15), 0.0, 0.0, math.sin(0.15)])  # 0.3 rad about z
    plan = find_space_contact_plan(scene, goal, config.search, mu)
    assert plan.success, plan.reason
    node = plan.nodes[0]
    controller = SpaceGraspController(scene, config.controller, mu=control_friction(config))
    q = np.ravel(node.q)
    p_tip, _, poses = controller.fingertips(q)
    n_W = BOX_FACE_NORMALS[[BOX_FACE_NAMES.index(f) for f in node.faces]]  # the start pose is unturned
    J_WC = controller.contact_jacobians(poses, -scene.tip_radius * n_W)
    p_WC = p_tip - scene.tip_radius * n_W
    lp = SpatialHoldingLp(scene.num_fingers, 8, 3)
    torque, x = lp.solve(
        edge_wrenches_W(p_WC, n_W, mu, 8),
        spatial_torque_rows(J_WC, n_W, mu, 8),
        scene.gravity_torques(node.q),
        [0.0, 0.0, scene.object.mass * scene.gravity, 0.0, 0.0, 0.0],
    )
    assert torque <= scene.tau_max.min()
    f_W = np.einsum("fm,fmc->fc", x.reshape(scene.num_fingers, 8), pyramid_edges(n_W, mu, 8))
    return SpaceReference.held(node.object_pose, q, p_tip, p_WC, f_W, duration)


def test_static_hold_of_the_initial_grasp(scene):
    """The cube in the search's initial grasp, 2 s in the discrete plant under the grasp controller: within 2 mm and
    1 deg of where it started, no drop; with the motors off (executor none) it falls."""
    config = Config()
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))
    reference = _initial_grasp_hold(scene, 2.0)
    held = simulate_space(reference, config, scene)
    assert not held.dropped
    assert held.t[-1] == pytest.approx(2.0)
    assert held.position_error_m.max() < 2e-3
    assert np.degrees(held.orientation_error_rad.max()) < 1.0
    assert np.all(np.abs(held.f_W[-1].sum(axis=0) - [0.0, 0.0, WEIGHT]) < 0.05)  # the fingers carry the weight
    fallen = simulate_space(reference, config, scene, executor="none")
    assert fallen.dropped
