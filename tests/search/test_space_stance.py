"""Statics in space: the 6-D frictional force-closure LP against closed forms on a cube, the holding
LP (smallest largest joint torque) against a hand-computed symmetric case, and both on fingerpro4."""

import numpy as np
import pytest

from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.scene.statics import edge_wrenches_W, finger_torques, grasp_matrix_3d_W, pyramid_edges
from trajectotree.search.grasp import SpatialClosure
from trajectotree.search.spatial_reach import FingerIk
from trajectotree.search.stance import SpatialHoldingLp, SpatialPushLp, spatial_push_capacity, spatial_torque_rows

A = 0.0325  # m, the cube's half-size
X, Y, Z = np.eye(3)
EDGES = 8


def test_two_opposite_face_centres_are_not_in_closure():
    result = SpatialClosure(mu=0.9, half_size=A).check(A * np.array([X, -X]), np.array([X, -X]))
    assert not result.in_closure and result.rank == 5  # nothing resists a torque about their line


def test_the_four_side_face_centres_are_in_closure_at_any_friction():
    n = np.array([X, -X, Y, -Y])
    for mu in (0.1, 0.5):
        assert SpatialClosure(mu=mu, half_size=A).check(A * n, n).in_closure


def test_a_set_needing_more_friction_than_given_is_not_in_closure():
    # +-x contacts offset by +-c along z, squeezed, turn the cube about y by 2 c N; only their z friction
    # answers it (the +-y face centres have no lever about y): a (f_z2 - f_z1) = c (N1 + N2) needs mu >= c / a
    c = A / 2
    p = np.array([[A, 0, c], [-A, 0, -c], [0, A, 0], [0, -A, 0]])
    n = np.array([X, -X, Y, -Y])
    assert not SpatialClosure(mu=0.45, half_size=A).check(p, n).in_closure
    assert SpatialClosure(mu=0.55, half_size=A).check(p, n).in_closure


def test_the_closure_lp_is_built_once_per_number_of_contacts():
    closure = SpatialClosure(mu=0.5, half_size=A)
    n = np.array([X, -X, Y, -Y])
    for shift in (0.0, 0.01, -0.01):
        closure.check(A * n + shift * Z, n)
    assert list(closure.lps) == [4] and closure.lps[4].lp_calls == 3


def test_pyramid_edges_and_the_grasp_matrix_agree():
    n = np.array([X, -Y, Z])
    p = A * n + 0.01
    edges = pyramid_edges(n, 0.5, EDGES)
    np.testing.assert_allclose(np.einsum("kmc,kc->km", edges, n), -1.0)  # unit pushing component
    np.testing.assert_allclose(np.linalg.norm(edges - (-n[:, None]), axis=2), 0.5)  # on the cone's rim
    # an edge force written as (lambda_n, lambda_1, lambda_2) gives the same wrench through G
    G, W = grasp_matrix_3d_W(p, n), edge_wrenches_W(p, n, 0.5, EDGES)
    t = np.linalg.lstsq(G, W, rcond=None)[0]
    np.testing.assert_allclose(G @ t, W, atol=1e-12)


def test_the_holding_lp_matches_a_symmetric_case_by_hand():
    # three Cartesian fingers (J = I: the torques are the force's components) under the bottom face at
    # the corners of an equilateral triangle: each carries a third of the weight, with no tangential force
    weight, rho = 0.094 * 9.81, 0.02
    angles = np.radians([90.0, 210.0, 330.0])
    p = np.stack([rho * np.cos(angles), rho * np.sin(angles), np.full(3, -A)], axis=1)
    n = np.tile(-Z, (3, 1))
    W = edge_wrenches_W(p, n, 0.5, EDGES)
    J = np.tile(np.eye(3), (3, 1, 1))
    lp = SpatialHoldingLp(3, EDGES, 3)
    for own_weight in (0.1, -0.2):  # N m on each finger's third joint
        tau_g = np.tile([0.0, 0.0, own_weight], (3, 1))
        t, x = lp.solve(W, spatial_torque_rows(J, n, 0.5, EDGES), tau_g, np.r_[0, 0, weight, 0, 0, 0])
        assert t == pytest.approx(abs(weight / 3 + own_weight), abs=1e-9)
        np.testing.assert_allclose(W @ x, [0, 0, weight, 0, 0, 0], atol=1e-9)


def test_the_holding_lp_refuses_a_stance_that_cannot_carry_the_weight():
    n = np.tile(Z, (3, 1))  # all three on the top face: they can only push down
    p = A * n + np.array([[0.01, 0, 0], [-0.01, 0.01, 0], [-0.01, -0.01, 0]])
    W = edge_wrenches_W(p, n, 0.5, EDGES)
    t, _ = SpatialHoldingLp(3, EDGES, 3).solve(
        W, spatial_torque_rows(np.tile(np.eye(3), (3, 1, 1)), n, 0.5, EDGES), np.zeros((3, 3)), [0, 0, 0.9, 0, 0, 0]
    )
    assert t == np.inf


@pytest.fixture(scope="module")
def side_grasp():
    """fingerpro4 with fingers 0-3 on the centres of the faces they stand behind (+x, +y, -x, -y)."""
    scene = build_space_scene("fingerpro4", mu=0.7, gravity=9.81)
    n = np.array([X, Y, -X, -Y])
    p = A * n
    q = np.array([FingerIk(scene, i).solve(START_POSE, p[i] + scene.tip_radius * n[i]) for i in range(4)])
    return scene, p, n, q


def test_three_fingers_of_the_hand_hold_the_cube_within_its_motors_with_their_own_weight(side_grasp):
    scene, p, n, q = side_grasp
    mu, stance = 0.5, [0, 1, 2]
    assert SpatialClosure(mu, A).check(p, n).in_closure and SpatialClosure(mu, A).check(p[stance], n[stance]).in_closure
    J = np.array([scene.fingers[i].jacobian(q[i], -scene.tip_radius * n[i]) for i in stance])
    W = edge_wrenches_W(p[stance], n[stance], mu, EDGES)
    rows = spatial_torque_rows(J, n[stance], mu, EDGES)
    tau_g = scene.gravity_torques(q)[stance]
    w_hold = np.r_[0, 0, scene.object.mass * scene.gravity, 0, 0, 0]
    lp = SpatialHoldingLp(3, EDGES, 3)
    t, x = lp.solve(W, rows, tau_g, w_hold)
    t_weightless, _ = lp.solve(W, rows, np.zeros_like(tau_g), w_hold)
    assert t <= 0.396  # N m, the motors
    assert abs(t - t_weightless) > 0.01  # N m: the fingers' own weight counts (here it helps them squeeze)
    f = np.einsum("kmc,km->kc", pyramid_edges(n[stance], mu, EDGES), x.reshape(3, EDGES))
    assert np.max(np.abs(finger_torques(J, f, tau_g))) == pytest.approx(t, abs=1e-9)
    push = spatial_push_capacity(SpatialPushLp(3, EDGES, 3, 8.0), W, rows, tau_g, scene.tau_max[stance], w_hold)
    assert push > 0.0  # N: it resists some push along each of +-x, +-y, +-z
