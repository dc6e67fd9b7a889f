"""Rolling contacts in space (search.spatial_rolling and the search in space's rolled stances): the sphere's roll
against the closed form r theta, none when the cube turns with the link or the link spins about the normal, the
face test's gap, the search's refusal of a stance whose contacts roll off their face, and a planned quarter turn
whose every stance holds the cube within the motors at the contacts its fingertips roll to."""

import math
from dataclasses import replace

import numpy as np
import pytest
from conftest import holding_torque

from trajectotree.config import Config, mu_plan
from trajectotree.geometry import BOX_FACE_NAMES, BOX_FACE_NORMALS, so3_exp
from trajectotree.refusal import RefusalKind
from trajectotree.scene.kinematics import SerialFinger
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import _SpaceSearch
from trajectotree.search.spatial_reach import box_transform
from trajectotree.search.spatial_rolling import (
    chain,
    chain_jacobian,
    link_rotations,
    moved_joints,
    on_face,
    rolled_step,
)

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])
EDGES = 8
RADIUS = 0.01  # m, fingerpro4's fingertip sphere
HALF = np.full(3, 0.0325)  # m, the 6.5 cm cube's half-sizes

# Three joints: about z through the origin, about x through (0, 0, 0.05) and (0, 0, 0.1); the tip at (0, 0, 0.15) m
# at q = 0.
FINGER = SerialFinger(
    p_W_joint=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.0, 0.0, 0.1]]),
    a_W=np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
    p_W_tip0=np.array([0.0, 0.0, 0.15]),
    q_lower=np.full(3, -math.pi),
    q_upper=np.full(3, math.pi),
)


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def test_the_link_rotation_is_the_product_of_the_joints_turns():
    q = np.array([0.3, -0.5, 0.7])
    expected = so3_exp([0.0, 0.0, 0.3]) @ so3_exp([-0.5, 0.0, 0.0]) @ so3_exp([0.7, 0.0, 0.0])
    np.testing.assert_allclose(link_rotations(FINGER, q), expected, atol=1e-12)
    np.testing.assert_allclose(link_rotations(FINGER, np.stack([q, q])), np.stack([expected] * 2), atol=1e-12)


def test_a_link_turning_on_a_still_cube_rolls_its_sphere_r_theta_along_the_face():
    theta, still = 0.2, np.eye(3)
    # on the +z face, the link turning theta about +x: the sphere rolls r theta along x cross z = -y
    step = rolled_step(FINGER, np.zeros(3), [0.0, theta, 0.0], still, still, np.array([0.0, 0.0, 1.0]), RADIUS)
    np.testing.assert_allclose(step, [0.0, -RADIUS * theta, 0.0], atol=1e-12)
    # the same turn about the face's normal is a spin: no roll
    spin = rolled_step(FINGER, np.zeros(3), [theta, 0.0, 0.0], still, still, np.array([0.0, 0.0, 1.0]), RADIUS)
    np.testing.assert_allclose(spin, 0.0, atol=1e-12)


def test_a_cube_turning_with_the_link_rolls_nothing():
    q1 = np.array([0.0, 0.1, 0.15])  # the link turns 0.25 rad about x
    step = rolled_step(FINGER, np.zeros(3), q1, np.eye(3), so3_exp([0.25, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.01)
    np.testing.assert_allclose(step, 0.0, atol=1e-12)


def test_a_contact_is_on_its_face_only_the_gap_short_of_its_edges():
    n_B = np.array([[0.0, 0.0, 1.0]] * 3)
    p_BC = np.array([[0.0, 0.0, 0.0325], [0.0305, 0.0, 0.0325], [0.0, -0.0306, 0.0325]])
    assert on_face(p_BC, n_B, HALF, 0.002).tolist() == [True, True, False]
    assert on_face(p_BC, n_B, HALF, 0.0).tolist() == [True, True, True]


def test_moved_joints_put_the_fingertip_on_a_point_a_few_mm_off():
    q = np.array([0.2, 0.5, 1.0])  # a bent finger, as one holding a face
    target = FINGER.fingertip(q) + np.array([0.004, -0.003, 0.002])
    np.testing.assert_allclose(FINGER.fingertip(moved_joints(FINGER, q, target)), target, atol=1e-7)


def test_the_search_refuses_a_stance_whose_contacts_roll_off_their_face(scene):
    config = Config()
    search = _SpaceSearch(scene, QUARTER_ABOUT_X, config.search, mu_plan(config.scene, config.search))
    root = search.roots()[0]
    held = {i: search.finger_reach(1, i, c, root.q[i]) for i, c in enumerate(root.contacts)}
    free = [  # the fingers that may move: the other three reach their contacts and are in closure
        i
        for i in range(scene.num_fingers)
        if all(held[j].reachable for j in range(scene.num_fingers) if j != i)
        and search.closed([c for j, c in enumerate(root.contacts) if j != i]).in_closure
    ]
    stance = tuple(j for j in range(scene.num_fingers) if j != free[0])
    _, torque, why = search.rolled_stance(root, 1, stance, held, search.mu)
    assert why is None and 0.0 < torque <= search.tau_limit
    # a holder's contact rolled to 1 mm from its face's edge (the gap is 2 mm): refused
    c = root.contacts[stance[0]]
    axis = next(k for k in range(3) if abs(search.n_B[c][k]) < 0.5)
    offset = np.zeros((scene.num_fingers, 3))
    offset[stance[0], axis] = (
        math.copysign(scene.object.half[axis] - 0.001, search.p_BC[c][axis] or 1.0) - search.p_BC[c][axis]
    )
    _, _, why = search.rolled_stance(replace(root, rolled=offset), 1, stance, held, search.mu)
    assert why is not None and why.kind == RefusalKind.STANCE_ROLLS_OFF
    # without rolled stances, nothing is checked
    off = _SpaceSearch(scene, QUARTER_ABOUT_X, replace(config.search, rolled_stances=False), search.mu)
    rolled, torque, why = off.rolled_stance(replace(root, rolled=offset), 1, stance, held, search.mu)
    assert why is None and torque == 0.0 and not rolled.any()


def test_a_planned_quarter_turn_holds_within_the_motors_where_its_fingertips_roll(scene, quarter_turn):
    config = Config()
    mu = mu_plan(config.scene, config.search)
    plan = quarter_turn(config.search)  # conftest's: searched once per process
    assert plan.success, plan.reason
    r, fingers = scene.tip_radius, scene.fingers
    rolled = np.zeros((scene.num_fingers, 3))  # m in B, each fingertip's roll since it landed
    largest = 0.0
    for a, b in zip(plan.nodes[:-1], plan.nodes[1:]):
        stance = [i for i in range(scene.num_fingers) if i != b.switching_finger]
        n_B = BOX_FACE_NORMALS[[BOX_FACE_NAMES.index(f) for f in a.faces]]
        R_a, R_b = (box_transform(n.object_pose).rotation().matrix() for n in (a, b))
        after = rolled.copy()
        for i in stance:
            after[i] += rolled_step(fingers[i], a.q[i], b.q[i], R_a, R_b, n_B[i], r)
        for node, offsets in ((a, rolled), (b, after)):
            p_BC = a.p_BC[stance] + offsets[stance]
            assert on_face(p_BC, n_B[stance], scene.object.half, config.search.rolled_corner_gap).all()
            p_WF = box_transform(node.object_pose).multiply((p_BC + r * n_B[stance]).T).T
            q = [moved_joints(fingers[i], node.q[i], p) for i, p in zip(stance, p_WF)]
            torque = holding_torque(scene, node.object_pose, p_BC, n_B[stance], q, stance, mu)
            assert torque <= 0.396 + 1e-9
            assert b.stance_torque >= torque - 1e-6
            largest = max(largest, float(np.max(np.linalg.norm(offsets, axis=1))))
        rolled = after
        if b.switching_finger is not None:
            rolled[b.switching_finger] = 0.0
    assert largest > 1e-3  # the fingertips do roll, by millimetres


def test_the_chain_is_serial_fingers_kinematics(scene):
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (5, 3))
    for finger in (FINGER, scene.fingers[1]):
        points, axes, tip, R = chain(finger, q)
        for mine, theirs in zip((points, axes, tip), finger.frames(q)):
            np.testing.assert_allclose(mine, theirs, atol=1e-14)
        np.testing.assert_allclose(chain_jacobian(points, axes, tip), finger.jacobian(q), atol=1e-14)
        np.testing.assert_allclose(R, link_rotations(finger, q), atol=0.0)
