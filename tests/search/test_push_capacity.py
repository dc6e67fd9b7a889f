"""The search's push capacity (search.push_capacity, trajectotree.search.stance.PushCapacityLp): the
LP against closed forms on the box, the order it gives a node's children, and the config's range."""

import dataclasses
import math

import numpy as np
import pytest

from trajectotree.config import ConfigError, SearchConfig
from trajectotree.contact_plan import ContactNode
from trajectotree.experiments.sweep import sample_goals
from trajectotree.scene.plant import build_scene
from trajectotree.scene.statics import grasp_matrix_W
from trajectotree.search.stance import PushCapacityLp
from trajectotree.search.tree import _Node, _Search, find_contact_plan

W, H, MU, F_MAX, WEIGHT = 0.2, 0.1, 0.5, 8.0, 0.05 * 9.81
LEFT, RIGHT, BOTTOM = ((-W / 2, 0.0), (-1.0, 0.0)), ((W / 2, 0.0), (1.0, 0.0)), ((0.0, -H / 2), (0.0, -1.0))


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def capacity(contacts, u, weight=0.0, torque=None) -> float:
    """N, the hardest push along u the box resists with `contacts` ((p, n) in W) upright;
    `torque` (A, bound): |A lambda| <= bound, else the motors do not bind."""
    p_WC = np.array([p for p, _ in contacts])
    n_W = np.array([n for _, n in contacts])
    k = len(contacts)
    A, bound = torque if torque is not None else (np.zeros((2 * k, 2 * k)), 1.0)
    lp = PushCapacityLp(k, MU, F_MAX)
    return lp.solve(grasp_matrix_W(p_WC, n_W), (A, -np.full(2 * k, bound), np.full(2 * k, bound)), [0, weight, 0], u)


def test_push_capacity_of_box_stances_matches_closed_forms():
    # a push along +x meets the right finger's normal force alone: f_max
    assert capacity([LEFT, RIGHT], (1.0, 0.0)) == pytest.approx(F_MAX, rel=1e-6)
    # along +y only the two side fingers' friction pushes back: 2 mu f_max
    assert capacity([LEFT, RIGHT], (0.0, 1.0)) == pytest.approx(2 * MU * F_MAX, rel=1e-6)
    # with the weight held, a finger below: a push down meets it and the friction beside it, less the
    # weight they also carry; a push up meets the friction alone, and the weight helps
    assert capacity([LEFT, RIGHT, BOTTOM], (0.0, -1.0), WEIGHT) == pytest.approx(
        F_MAX * (1 + 2 * MU) - WEIGHT, rel=1e-6
    )
    assert capacity([LEFT, RIGHT, BOTTOM], (0.0, 1.0), WEIGHT) == pytest.approx(2 * MU * F_MAX + WEIGHT, rel=1e-6)
    # a motor that binds: the right finger's normal force costs 0.1 and 0.05 N m per newton on its
    # joints, each joint within 0.2 N m, so it pushes 2 N at most
    A = np.zeros((4, 4))
    A[2:, 2] = (0.1, 0.05)
    assert capacity([LEFT, RIGHT], (1.0, 0.0), torque=(A, 0.2)) == pytest.approx(2.0, rel=1e-6)
    # two fingers on one face cannot hold the weight: no push is resisted
    assert capacity([LEFT, ((-W / 2, 0.03), (-1.0, 0.0))], (1.0, 0.0), WEIGHT) == -math.inf


def test_children_come_in_order_of_their_stances_push_shortfall(scene):
    grasp = (0.54, 0.12, 0.36, 0.48)
    # toward goal 1.0 fingers 2 and 3 may switch, or none; toward -1.0 finger 0 alone, whose children's order
    # the shortfall they all share cannot change
    for goal, movers in ((1.0, {2, 3, None}), (-1.0, {0})):
        for target in (0.0, 6.0):
            config = SearchConfig(initial_arclengths=grasp, friction_safety=1.0, push_capacity=target)
            search = _Search(scene, goal, config)
            search.plan_switch_bounds([{a} for a in grasp])
            root = _Node(0, grasp, None, None)
            rows = search.neighbors(root)
            assert {child.switching_finger for *_, child in rows} == movers

            siblings = search.siblings(root, rows, toward_goal=False)
            popped = [siblings.pop() for _ in rows]
            assert not siblings
            # every LP solved (after the pops, which solve them only as far as the order needs), as the
            # heap of old ordered them
            resisted = {f: search.stance.push_capacity(root, 1, f) for f in movers}
            shortfall = {f: max(0.0, target - resisted[f]) if target else 0.0 for f in movers}
            expected = sorted(rows, key=lambda row: (shortfall[row[2].switching_finger], row[1], rows.index(row)))
            assert popped == [child for *_, child in expected]
            if not target:
                assert set(shortfall.values()) == {0.0}
            elif len(movers) > 1:  # the stances toward 1.0 resist < 6 N: their shortfall orders the children
                assert len(set(shortfall.values())) > 1


def test_the_push_order_strengthens_the_weakest_stance_of_goal_minus_0_731(scene):
    """Seed 0's goal 25 (-0.731 rad): in the paper's order its plan switches over a stance that resists
    less than 3 N along one of +-x, +-y (1.38 N); in the push order every stance resists more than that
    (6.18 N). Since the fingers are kept apart, goal 0.861's push-order plan no longer shows this (its
    weakest stance resists 2.06 N in both orders). Each node reports its stance's capacity (the search's
    LP, in plan.json too)."""
    goal = float(sample_goals(60, 0)[25])
    assert goal == pytest.approx(-0.731, abs=1e-3)
    default = SearchConfig()
    paper = dataclasses.replace(default, push_capacity=0.0)
    weakest = {}
    for config in (paper, default):
        plan = find_contact_plan(scene, goal, config)
        assert plan.success and plan.nodes[0].stance_push_capacity is None
        search = _Search(scene, goal, config)
        for n, (a, b) in enumerate(zip(plan.nodes[:-1], plan.nodes[1:])):
            parent = _Node(n, tuple(a.arclengths), None, None)
            resisted = search.stance.push_capacity(parent, n + 1, b.switching_finger)  # closed-form IK, not its table
            assert b.stance_push_capacity == pytest.approx(resisted, rel=1e-9)
            assert ContactNode.from_json(b.to_json()).stance_push_capacity == b.stance_push_capacity
        weakest[config] = min(b.stance_push_capacity for b in plan.nodes[1:] if b.switching_finger is not None)
    assert weakest[paper] < 3.0 < weakest[default]


@pytest.mark.parametrize(
    ("field", "value"), [("push_capacity", -1.0), ("push_capacity", 101.0), ("push_normal_force", 0.0)]
)
def test_push_capacity_settings_out_of_range(field, value):
    with pytest.raises(ConfigError, match=rf"search.{field} = "):
        SearchConfig(**{field: value})


def test_a_fingers_gravity_torques_are_the_controllers(scene):
    # the grasp controller's gravity compensation (closed forms checked against the plant in its tests)
    from trajectotree.execution.fingers import HandKinematics

    q = np.random.default_rng(0).uniform(-1.5, 1.5, (scene.num_fingers, 2))
    g_hand = HandKinematics(scene.fingers, scene.config.gravity)(q.ravel())[2]
    for i, finger in enumerate(scene.fingers):
        np.testing.assert_allclose(finger.gravity_torques(q[i], scene.config.gravity), g_hand[i], rtol=1e-12)
