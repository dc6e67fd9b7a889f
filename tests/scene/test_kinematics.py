"""The closed-form finger kinematics (trajectotree.scene.kinematics) against Drake's plant of the
SDF hand, and its IK: round trips, branch and tolerance options, unreachable targets."""

import dataclasses

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable

from trajectotree.scene.kinematics import TwoLinkFinger
from trajectotree.scene.plant import NUM_FINGERS, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def random_q(scene, n, seed):
    """(n, 4, 2) joint angles within each finger's limits."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(f.q_lower, f.q_upper, (n, 2)) for f in scene.fingers], axis=1)


def plant_tips_and_jacobians(scene, q):
    """p_WF (4, 2) and J_WF (4, 2, 2) of the tip frames, from the plant at hand angles q (4, 2)."""
    plant, ctx = scene.plant, scene.plant.CreateDefaultContext()
    plant.SetPositions(ctx, scene.positions((0.02, -0.01, 0.4), q.ravel()))
    W = plant.world_frame()
    p = np.array(
        [plant.CalcPointsPositions(ctx, scene.tip_frame(i), np.zeros(3), W)[:2, 0] for i in range(NUM_FINGERS)]
    )
    J = np.array(
        [
            plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, scene.tip_frame(i), np.zeros(3), W, W)[
                :2, scene.hand_v_indices[2 * i : 2 * i + 2]
            ]
            for i in range(NUM_FINGERS)
        ]
    )
    return p, J


def test_forward_kinematics_and_jacobian_match_the_plant(scene):
    hand = TwoLinkFinger.stack(scene.fingers)
    qs = np.concatenate([random_q(scene, 10, seed=0), np.random.default_rng(1).uniform(-3, 3, (10, 4, 2))])
    tips, jacobians = hand.fingertip(qs), hand.jacobian(qs)  # batched over (20, 4)
    for q, tip, jac in zip(qs, tips, jacobians):
        p_plant, J_plant = plant_tips_and_jacobians(scene, q)
        np.testing.assert_allclose(tip, p_plant, atol=1e-12)
        np.testing.assert_allclose(jac, J_plant, atol=1e-12)
        for i, finger in enumerate(scene.fingers):  # one finger at a time
            np.testing.assert_allclose(finger.fingertip(q[i]), p_plant[i], atol=1e-12)
            np.testing.assert_allclose(finger.jacobian(q[i]), J_plant[i], atol=1e-12)
            np.testing.assert_allclose(finger.elbow(q[i]) + finger.links(q[i])[1], p_plant[i], atol=1e-12)
            _, _, r1, r2 = finger.links_one(*q[i].tolist())  # the scalar (math) form
            np.testing.assert_allclose(finger.p_W_base + r1 + r2, p_plant[i], atol=1e-12)


def test_ik_round_trips_for_one_and_many_targets(scene):
    qs = random_q(scene, 50, seed=2)
    hand = TwoLinkFinger.stack(scene.fingers)
    np.testing.assert_allclose(hand.ik(hand.fingertip(qs)), qs, atol=1e-9)  # all fingers at once
    for i, finger in enumerate(scene.fingers):
        tips = finger.fingertip(qs[:, i])
        np.testing.assert_allclose(finger.ik(tips), qs[:, i], atol=1e-9)
        np.testing.assert_allclose(finger.ik(tips, elbow=1), qs[:, i], atol=1e-9)
        for tip, q in zip(tips, qs[:, i]):
            solutions = finger.ik_solutions(tip)
            assert len(solutions) == 1  # q2 in [0.1, 2.6]: one elbow branch
            np.testing.assert_allclose(solutions[0], q, atol=1e-9)
            np.testing.assert_allclose(finger.ik_one(tip), q, atol=1e-9)


def test_unreachable_targets_give_no_solution(scene):
    finger = scene.fingers[0]
    far = finger.p_W_base + 1.01 * (finger.l1 + finger.l2) * np.array([1.0, 0.0])  # beyond the links
    near = finger.p_W_base + 0.5 * abs(finger.l1 - finger.l2) * np.array([0.0, 1.0])  # inside the inner circle
    assert finger.ik_solutions(far) == [] and finger.ik_solutions(near) == []
    assert np.all(np.isnan(finger.ik(np.array([far, near]))))
    assert finger.ik_one(far) is None
    # Within reach, but only with q1 = 1 beyond a tight joint-1 limit (the other branch has q2 < 0.1).
    tight = dataclasses.replace(finger, q_lower=np.array([-0.1, 0.1]), q_upper=np.array([0.1, 2.6]))
    target = tight.fingertip(np.array([1.0, 1.0]))
    assert tight.ik_solutions(target) == [] and tight.ik_one(target) is None
    assert finger.ik_solutions(target) != []


def test_tolerance_widens_the_limits(scene):
    finger = scene.fingers[1]
    q = np.array([0.2, finger.q_upper[1] + 5e-10])  # just past the joint-2 limit
    target = finger.fingertip(q)
    assert finger.ik_one(target) is None
    np.testing.assert_allclose(finger.ik_one(target, tolerance=1e-9), q, atol=1e-9)


def test_elbow_branches_and_q1_wraps_in_candidate_order(scene):
    """Wide limits: both elbow branches and q1 + 2 pi are solutions; ik_solutions lists them
    in the module's order and ik picks the first (or the asked branch)."""
    wide = dataclasses.replace(scene.fingers[2], q_lower=np.array([-4.0, -2.6]), q_upper=np.array([4.0, 2.6]))
    q = np.array([-3.0, 1.2])
    target = wide.fingertip(q)
    solutions = wide.ik_solutions(target)
    assert len(solutions) == 3  # elbow +: q1 and q1 + 2 pi; elbow -: one wrap in limits
    np.testing.assert_allclose(solutions[0], q, atol=1e-9)
    np.testing.assert_allclose(solutions[1], q + [2 * np.pi, 0.0], atol=1e-9)
    assert solutions[2][1] == pytest.approx(-1.2)
    for s in solutions:
        np.testing.assert_allclose(wide.fingertip(s), target, atol=1e-12)
    np.testing.assert_allclose(wide.ik(target), solutions[0], atol=1e-12)
    np.testing.assert_allclose(wide.ik(target, elbow=-1), solutions[2], atol=1e-12)


def test_ik_picks_the_first_of_ik_solutions(scene):
    rng = np.random.default_rng(3)
    for finger in scene.fingers:
        targets = finger.p_W_base + rng.uniform(-0.2, 0.2, (300, 2))
        vectorized = finger.ik(targets)
        for target, q in zip(targets, vectorized):
            solutions = finger.ik_solutions(target)
            assert np.isnan(q[0]) == (not solutions)
            if solutions:
                np.testing.assert_allclose(q, solutions[0], atol=1e-12)
