"""Rolling contacts in the search (search.rolled_stances): a fingertip sphere that sticks to a
face rolls along it by r times its second link's turn relative to the object. Seed-0 goal 50
(1.804 rad) dropped its box at 7.4 s under the keyframes formulation: its stance of fingers
0, 2, 3 while finger 1 moves from node 3 to node 4 is in closure at mu_plan at its planned
contacts but not at the contacts its fingertips roll to (that plan had fingers overlapping; since
the fingers are kept apart, goal 3's plan shows the case). The rolled contacts are recomputed here
independently: the link angles from the plant's kinematics at each node's (Drake IK)
joint angles, the friction from grasp.required_mu_many."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, ConfigError, ObjectConfig, SceneConfig, SearchConfig
from trajectotree.experiments.sweep import sample_goals
from trajectotree.geometry import SMOOTH_VERTEX_ANGLE
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.grasp import required_mu_many
from trajectotree.search.tree import find_contact_plan


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def link2_angles(scene, q) -> np.ndarray:
    """(4,) the angle in W of each finger's second link body at joint angles q (8,), by the plant."""
    plant = scene.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, scene.hand, q)
    out = np.empty(NUM_FINGERS)
    for i in range(NUM_FINGERS):
        R = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName(f"finger{i}_link2", scene.hand)).rotation().matrix()
        out[i] = np.arctan2(R[1, 0], R[0, 0])
    return out


def rolled_stance_mus(scene, plan) -> list[tuple[int, float, float]]:
    """(node n, required mu of the stance at node n - 1, at node n) at its rolled contacts for
    every node n reached by a switch: the holding fingers' contacts rolled by r times their
    link's turn relative to the object since they landed. Asserts the rolls stay on the face."""
    shape, r = scene.config.shape, scene.tip_radius
    nodes = plan.nodes
    turn = [link2_angles(scene, n.q) - n.object_pose[2] for n in nodes]
    corners = shape.corner_arclengths()
    out = []
    for n in range(1, len(nodes)):
        moving = nodes[n].switching_finger
        if moving is None:
            continue
        stance = [j for j in range(NUM_FINGERS) if j != moving]
        mus = []
        for m in (n - 1, n):
            rolled = []
            for j in stance:
                landed = max([k for k in range(1, m + 1) if nodes[k].switching_finger == j], default=0)
                s = nodes[m].arclengths[j]
                delta = np.angle(np.exp(1j * (turn[m][j] - turn[landed][j])))
                s_rolled = (s + r * delta) % shape.perimeter
                assert np.searchsorted(corners, s_rolled, side="right") == np.searchsorted(corners, s, side="right")
                rolled.append(s_rolled)
            p_BC, n_B = shape.points(np.array(rolled))
            mus.append(float(required_mu_many(p_BC[None], n_B[None])[0]))
        out.append((n, *mus))
    return out


def test_goal_minus_3038_stances_hold_at_their_rolled_contacts(scene):
    goal = float(sample_goals(60, 0)[3])
    assert goal == pytest.approx(-3.0377, abs=1e-4)
    config = dataclasses.replace(Config().search, push_capacity=0.0)  # the paper's order, whose plan this case is
    mu_plan = config.friction_safety * scene.config.mu
    fixed = find_contact_plan(scene, goal, dataclasses.replace(config, rolled_stances=False))
    rolling = find_contact_plan(scene, goal, config)
    assert fixed.success and rolling.success
    # the plan of the fixed-contact search: node 7 -> 8 (finger 3 moves) holds with fingers 0, 1, 2
    # at mu 0.40 planned, but more than mu_plan (0.645) where they have rolled to by node 8
    worst_fixed = max(rolled_stance_mus(scene, fixed), key=lambda row: max(row[1:]))
    assert worst_fixed[0] == 8 and fixed.nodes[8].switching_finger == 3
    assert fixed.nodes[8].stance_required_mu < mu_plan < worst_fixed[2]
    # the rolling-aware search's plan: every stance in closure at mu_plan at both ends, rolled
    assert all(max(mus) <= mu_plan + 1e-6 for _, *mus in rolled_stance_mus(scene, rolling))
    assert [tuple(n.arclengths) for n in rolling.nodes] != [tuple(n.arclengths) for n in fixed.nodes]


def rolled_corner_gaps(scene, plan) -> list[float]:
    """m, for every segment's holding fingers (all but the switching one, all four when none
    switches) at both its ends: each rolled contact's arclength to the nearest vertex that ends
    a side (one turning SMOOTH_VERTEX_ANGLE or more)."""
    shape, r, nodes = scene.config.shape, scene.tip_radius, plan.nodes
    ends = shape.corner_arclengths()[shape.exterior_angles >= SMOOTH_VERTEX_ANGLE]
    turn = [link2_angles(scene, n.q) - n.object_pose[2] for n in nodes]
    gaps = []
    for n in range(1, len(nodes)):
        stance = [j for j in range(NUM_FINGERS) if j != nodes[n].switching_finger]
        for m in (n - 1, n):
            for j in stance:
                landed = max([k for k in range(1, m + 1) if nodes[k].switching_finger == j], default=0)
                delta = np.angle(np.exp(1j * (turn[m][j] - turn[landed][j])))
                s = (nodes[m].arclengths[j] + r * delta) % shape.perimeter
                d = np.abs(s - ends)
                gaps.append(float(np.min(np.minimum(d, shape.perimeter - d))))
    return gaps


def test_rolled_contacts_stay_short_of_corners():
    """The polygon gallery's quadrilateral, goal -1.446 (seed-0 goal 1 of 12): without the corner gap
    the plan's finger 1, planned 13.5 mm from a 56 deg corner, rolls to within 0.1 mm of it (in
    simulation it pivoted over the corner and the object dropped); with it, no rolled contact of the
    plan comes closer than search.rolled_corner_gap to a corner."""
    vertices = ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04))
    config = Config(scene=SceneConfig(object=ObjectConfig(vertices=vertices)))
    scene = build_scene(config.scene)
    goal = float(sample_goals(12, 0)[1])
    assert goal == pytest.approx(-1.4465, abs=1e-4)
    gapless = find_contact_plan(scene, goal, dataclasses.replace(config.search, rolled_corner_gap=0.0))
    kept = find_contact_plan(scene, goal, config.search)
    assert gapless.success and kept.success
    assert min(rolled_corner_gaps(scene, gapless)) < 1e-4
    assert min(rolled_corner_gaps(scene, kept)) >= config.search.rolled_corner_gap - 2e-4  # closed-form IK vs Drake's


def test_rolled_corner_gap_is_checked():
    with pytest.raises(ConfigError, match="search.rolled_corner_gap"):
        SearchConfig(rolled_corner_gap=-0.001)


def test_rolled_stances_must_be_a_bool():
    with pytest.raises(ConfigError, match="search.rolled_stances"):
        SearchConfig(rolled_stances=1)
