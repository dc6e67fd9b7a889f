"""Plans whose every stance met the stance margin still dropped at friction 0.4 (issue 37, branch drop37): the margin
was the world's friction 0.4, but the closed loop's grasp QP gives its cones controller.grasp.friction_safety x the
estimate, 0.32 there, and the swings' stances of seed-0 goal 13's plan needed 0.35-0.37 within the motors. The
margin is now that QP's friction (docs/measurements.md "Why plans at the margin drop")."""

import json
from dataclasses import replace

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, mu_plan
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import _SpaceSearch, space_initial_grasp
from trajectotree.search.tree import SearchClock

WORLD_MU = 0.4  # the closed loop's slippery world (planned at scene.mu 0.7)
# seed-0 SO(3) goal 13 ([qw, qx, qy, qz]): its plan at the margin 0.4 had 9/9 stances there and dropped at friction
# 0.4 (4.50 s) and at mass x1.5 (4.71 s), closed loop (/work/sweeps/share50)
GOAL_13 = (0.3158497023753437, -0.3766650622404895, -0.8705920563605003, -0.020781429180171163)
QUARTER_ABOUT_X = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])


def test_the_margin_is_the_closed_loop_s_cones_in_the_slippery_world():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    search = _SpaceSearch(scene, np.array(GOAL_13), config.search, mu_plan(config.scene, config.search))
    closed_loop_cones = config.controller.grasp.friction_safety * WORLD_MU
    assert search.mu_hold == pytest.approx(closed_loop_cones, abs=1e-4)
    # prefer: then the fallback, the world's own friction, then mu_plan
    assert search.hold_frictions == pytest.approx((closed_loop_cones, WORLD_MU, 0.49), abs=1e-4)
    # plan.json says at which of them each stance holds (the initial grasp's here)
    node = space_initial_grasp(scene, GOAL_13, config.search, search.mu).to_json()["contact_sequence"][0]
    assert node["stance_mu"] in search.hold_frictions and node["stance_margin"] == (node["stance_mu"] == search.mu_hold)


def test_prefer_searches_the_margin_then_the_fallback_then_every_stance():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    search = _SpaceSearch(scene, np.array(GOAL_13), config.search, mu_plan(config.scene, config.search))
    passes = search.passes()
    assert [frictions for frictions, _ in passes] == [search.hold_frictions[:k] for k in (1, 2, 3)]
    share = config.search.space_margin_first_share  # of the budgets left, each margin pass
    ends = [1.0 - (1.0 - share), 1.0 - (1.0 - share) ** 2, 1.0]
    budget = config.search.space_time_budget_s
    assert [b.time_budget_s for _, b in passes] == pytest.approx([e * budget for e in ends])
    assert passes[-1][1] == search.config


@pytest.mark.slow  # the search, ~8 s of CPU
def test_goal_13_s_stances_all_hold_at_the_closed_loop_s_cones(capsys):
    """Goal 13's plan at the margin 0.4 dropped at friction 0.4 and mass x1.5; its plan now has every stance at 0.32.
    That plan held in both worlds closed loop (the sweeps of docs/measurements.md "Issue 37's acceptance on the
    default": executing it here would add two 8.5 s runs and a 12 s trajectory optimization to the suite)."""
    goal = [str(v) for v in GOAL_13]
    assert main(["search", "--hand", "fingerpro4", "--goal-quat", *goal, "--json"]) == 0
    contact_plan = json.loads(capsys.readouterr().out)
    assert contact_plan["success"] and contact_plan["mu_margin"] == pytest.approx(0.32, abs=1e-3)
    assert contact_plan["margin_stances"] == contact_plan["stances"] == 9
    assert [n["stance_mu"] for n in contact_plan["contact_sequence"]] == [contact_plan["mu_margin"]] * 9


@pytest.mark.slow  # none's search and every node's children on its path, ~8 s of CPU
def test_prefer_orders_children_by_the_least_friction_their_stance_holds_at():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    mu = mu_plan(config.scene, config.search)
    prefer = _SpaceSearch(scene, QUARTER_ABOUT_X, config.search, mu)
    none = _SpaceSearch(scene, QUARTER_ABOUT_X, replace(config.search, space_stance_margin="none"), mu)
    leaf, why = none.run(none.roots()[0], SearchClock.start(none.config), none.config)
    assert leaf is not None, why
    seen = set()
    node = leaf.parent
    while node is not None:
        depth = node.depth + 1
        held = {i: prefer.finger_reach(depth, i, c, node.q[i]) for i, c in enumerate(node.contacts)}
        ranks = []
        for child in prefer.neighbors(node):
            stance = tuple(i for i in range(scene.num_fingers) if i != child.finger)
            kept, _ = prefer.stance(node, depth, stance, held)
            ranks.append(kept[3])
            assert child.stance_mu == prefer.hold_frictions[kept[3]]
        assert ranks == sorted(ranks)  # the margin's stances, then the fallback's, then those at mu_plan alone
        seen |= set(ranks)
        node = node.parent
    assert seen == {0, 1, 2}  # the quarter turn's plan passes nodes with children at each friction
