"""The stance margin as a preference (search.space_stance_margin prefer, issue 37): a stance that holds the cube within
the motors only at mu_plan is taken where no stance at the margin's friction is found, so a goal keeps the plan
the search without the margin finds; where a plan with margin stances alone exists, prefer's is require's; plan.json
counts the stances at the margin; the search in space spends its own budget (search.space_time_budget_s), its margin
pass a share of it (the options' bad values: test_space_margins)."""

from dataclasses import replace

import numpy as np
import pytest

from trajectotree.config import Config, SearchConfig, mu_plan
from trajectotree.refusal import RefusalKind
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import _SpaceSearch, find_space_contact_plan
from trajectotree.search.tree import SearchClock

QUARTER_ABOUT_X = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])
AT_04 = 0.5714  # search.space_stance_friction_safety: 0.5714 x scene.mu 0.7 = friction 0.4
AT_021 = 0.3  # 0.3 x 0.7 = 0.21: the quarter turn's first root holds there, the stances after it do not


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def _config(mode: str, safety: float = AT_04, **more) -> SearchConfig:
    return replace(Config().search, space_stance_margin=mode, space_stance_friction_safety=safety, **more)


@pytest.fixture
def plan_of(quarter_turn):
    """(mode, safety, options) -> the quarter turn's plan with _config's settings: conftest's, each settings' plan
    searched once per process (prefer at AT_04 is the default search's)."""
    return lambda mode, safety=AT_04, **more: quarter_turn(_config(mode, safety, **more))


def _search(scene, mode: str, safety: float = AT_04) -> _SpaceSearch:
    config = _config(mode, safety)
    return _SpaceSearch(scene, QUARTER_ABOUT_X, config, mu_plan(Config().scene, config))


def _sequence(plan) -> list:
    return [(n.switching_finger, n.faces, n.p_BC.round(9).tolist()) for n in plan.nodes]


def _none_path(search: _SpaceSearch) -> list:
    """The nodes, root first, of the plan the search without a margin finds from its first root (goal's excluded)."""
    leaf, why = search.run(search.roots()[0], SearchClock.start(search.config), search.config)
    assert leaf is not None, why
    path = [leaf.parent]
    while path[-1].parent is not None:
        path.append(path[-1].parent)
    return path[::-1]


def test_prefer_orders_the_stances_under_the_margin_after_the_others_and_keeps_them(scene):
    prefer, require, none = (_search(scene, mode) for mode in ("prefer", "require", "none"))
    assert prefer.hold_frictions == pytest.approx((0.4, 0.49), abs=1e-4)
    assert none.hold_frictions == pytest.approx((0.49,))
    # a node of none's plan with children on both sides of the margin (some stances hold at 0.4, some only at 0.49)
    node, children = next(
        (n, c) for n in _none_path(none) for c in [prefer.neighbors(n)] if len({child.stance_mu for child in c}) == 2
    )
    margins = [c.stance_mu == prefer.mu_hold for c in children]
    assert margins == sorted(margins, reverse=True)  # every margin stance before any that holds only at mu_plan
    # the same children as without the margin (none is lost), each marked as require's check says
    assert sorted((-1 if c.finger is None else c.finger, c.contacts) for c in children) == sorted(
        (-1 if c.finger is None else c.finger, c.contacts) for c in none.neighbors(node)
    )
    held = {i: require.finger_reach(node.depth + 1, i, c, node.q[i]) for i, c in enumerate(node.contacts)}
    for child in children:
        stance = tuple(i for i in range(scene.num_fingers) if i != child.finger)
        kept, why = require.stance(node, node.depth + 1, stance, held)
        assert (kept is not None) == (child.stance_mu == prefer.mu_hold)
        if kept is None:
            assert why.kind == RefusalKind.STANCE_OVER_MOTORS


@pytest.mark.slow  # three searches, ~7 s of CPU
def test_prefer_finds_require_s_plan_where_one_exists(plan_of):
    require, prefer = plan_of("require"), plan_of("prefer")
    assert require.success and prefer.success, prefer.reason
    assert _sequence(prefer) == _sequence(require)
    assert prefer.margin_stances == len(prefer.nodes) == require.margin_stances
    assert prefer.mu_margin == pytest.approx(0.4, abs=1e-4)
    # the greedy pass alone (share 0) takes a stance under the margin at the first node without a margin child: its
    # first root has no plan with margin stances alone, so it keeps fewer at the margin than the first pass finds
    greedy = plan_of("prefer", space_margin_first_share=0.0)
    assert greedy.success and greedy.margin_stances < prefer.margin_stances


@pytest.mark.slow  # four searches, ~7 s of CPU
def test_prefer_keeps_a_plan_where_the_margin_allows_none(plan_of):
    # at friction 0.07 no stance holds the cube within the motors: require has no plan, prefer has none's (no fallback
    # friction between the margin's and mu_plan: search.space_stance_fallback_safety at the margin's is ignored)
    require, prefer, none = (
        plan_of(mode, 0.1, space_stance_fallback_safety=0.1) for mode in ("require", "prefer", "none")
    )
    assert not require.success
    assert prefer.success and none.success, prefer.reason
    assert _sequence(prefer) == _sequence(none)
    assert prefer.margin_stances == 0 and none.margin_stances == len(none.nodes)  # none's margin is mu_plan
    saved = prefer.to_json()
    assert saved["margin_stances"] == 0 and saved["stances"] == len(prefer.nodes)
    assert saved["mu_margin"] == pytest.approx(0.07)
    assert [n["stance_margin"] for n in saved["contact_sequence"]] == [False] * len(prefer.nodes)
    # where the margin binds on some stances only, the plan keeps those that meet it and says how many
    some = plan_of("prefer", AT_021)
    assert some.success and 0 < some.margin_stances < len(some.nodes)


def test_the_search_in_space_spends_its_own_budget_its_margin_pass_a_share_of_it(scene):
    config = replace(Config().search, time_budget_s=0.5, space_time_budget_s=50.0, space_margin_first_share=0.5)
    search = _SpaceSearch(scene, QUARTER_ABOUT_X, config, mu_plan(Config().scene, config))
    budgets = [budgets.time_budget_s for _, budgets in search.passes()]
    assert budgets == pytest.approx([25.0, 37.5, 50.0])  # s: the passes end at 0.5, 0.75 and 1 of it, not the plane's
    # a budget in space spent before the first expansion refuses, however long the plane's
    spent = replace(Config().search, space_time_budget_s=1e-6, time_budget_s=600.0)
    plan = find_space_contact_plan(scene, QUARTER_ABOUT_X, spent, mu_plan(Config().scene, spent))
    assert not plan.success and plan.refusal.last_searched.refusal.kind == RefusalKind.TIME_BUDGET, plan.reason
    assert plan.stats.expanded == 0
