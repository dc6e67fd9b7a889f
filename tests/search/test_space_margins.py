"""Headroom in the search in space's stances (issue 37: closed loop at mass x1.5 and friction 0.4):
search.space_torque_fraction (a stance holds the cube within that fraction of the motors' limit) and
search.space_stance_friction_safety (with cones at that x scene.mu, space_stance_margin require); the search refuses a
stance over either, a plan with both margins keeps them at every stance, and every stance-margin field's bad value
(these two, space_stance_margin, space_stance_fallback_safety, space_margin_first_share, space_time_budget_s) is a
ConfigError and exits 2 naming the value and the valid range or choices."""

from dataclasses import replace

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, SearchConfig, mu_plan
from trajectotree.refusal import RefusalKind
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import _SpaceSearch

QUARTER_ABOUT_X = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])
TAU_MAX = 0.396  # N m, fingerpro4's motors


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def _search(scene, **margins) -> _SpaceSearch:
    """The search for a quarter turn about x with `margins` set (the stance friction's required), the others at no
    margin."""
    config = Config()
    none = dict(space_torque_fraction=1.0, space_stance_margin="require", space_stance_friction_safety=1.0)
    search = replace(config.search, **{**none, **margins})
    return _SpaceSearch(scene, QUARTER_ABOUT_X, search, mu_plan(config.scene, search))


def _first_stance(search: _SpaceSearch):
    """(root, stance, held): the first root and the stance of its first finger that may move to the next node."""
    root = search.roots()[0]
    held = {i: search.finger_reach(1, i, c, root.q[i]) for i, c in enumerate(root.contacts)}
    n = search.scene.num_fingers
    free = next(
        i
        for i in range(n)
        if all(held[j].reachable for j in range(n) if j != i)
        and search.closed([c for j, c in enumerate(root.contacts) if j != i]).in_closure
    )
    return root, tuple(j for j in range(n) if j != free), held


def test_a_stance_over_the_torque_fraction_is_refused(scene):
    search = _search(scene)
    root, stance, held = _first_stance(search)
    _, torque, why = search.rolled_stance(root, 1, stance, held, search.mu_hold)
    assert why is None and 0.0 < torque <= TAU_MAX
    fraction = torque / TAU_MAX
    # the same stance with the limit just under and just over what it needs (the same root: the search's roots
    # are checked at the limit too, so the first root is taken from the search without a margin)
    tight = _search(scene, space_torque_fraction=0.99 * fraction)
    assert tight.tau_limit == pytest.approx(0.99 * torque)
    _, _, why = tight.rolled_stance(root, 1, stance, held, tight.mu_hold)
    assert why is not None and why.kind == RefusalKind.STANCE_OVER_MOTORS
    assert why.limit == pytest.approx(0.99 * torque)
    loose = _search(scene, space_torque_fraction=min(1.0, 1.01 * fraction))
    _, _, why = loose.rolled_stance(root, 1, stance, held, loose.mu_hold)
    assert why is None


def test_a_stance_that_cannot_hold_at_the_stance_friction_is_refused(scene):
    search = _search(scene)
    root, stance, held = _first_stance(search)
    _, at_plan, _ = search.rolled_stance(root, 1, stance, held, search.mu_hold)
    at_04 = _search(scene, space_stance_friction_safety=0.4 / 0.7)
    assert at_04.mu_hold == pytest.approx(0.4)
    _, torque, _ = at_04.rolled_stance(root, 1, stance, held, at_04.mu_hold)
    assert torque >= at_plan - 1e-9  # narrower cones: the squeeze, so the torque, can only grow
    # at friction 0.07 the stance cannot hold the cube within the motors
    at_007 = _search(scene, space_stance_friction_safety=0.1)
    _, torque, why = at_007.rolled_stance(root, 1, stance, held, at_007.mu_hold)
    assert why is not None and why.kind == RefusalKind.STANCE_OVER_MOTORS and torque > TAU_MAX
    # a stance friction above friction_safety does not loosen the stances past mu_plan
    assert _search(scene, space_stance_friction_safety=1.0).mu_hold == pytest.approx(search.mu)


def test_a_plan_with_both_margins_keeps_them_at_every_stance(quarter_turn):
    config = Config()
    search = replace(
        config.search, space_torque_fraction=0.9, space_stance_margin="require", space_stance_friction_safety=0.5
    )
    plan = quarter_turn(search)  # conftest's: searched once per process
    assert plan.success, plan.reason
    torques = [n.stance_torque for n in plan.nodes[1:]]
    assert max(torques) <= 0.9 * TAU_MAX + 1e-9
    # without the margins the same goal's plan uses more of the motors somewhere: the margin did bind
    none = replace(config.search, space_torque_fraction=1.0, space_stance_margin="none")
    free = quarter_turn(none)
    assert max(n.stance_torque for n in free.nodes[1:]) > max(torques)


@pytest.mark.parametrize(
    "field, value, valid",
    [
        ("space_torque_fraction", 0.0, "(0, 1]"),
        ("space_torque_fraction", 1.2, "(0, 1]"),
        ("space_stance_friction_safety", -0.1, "(0, 1]"),
        ("space_time_budget_s", 0.0, "86400"),
        ("space_stance_margin", "sometimes", "none, prefer, require"),
        ("space_stance_margin", False, "none, prefer, require"),
        ("space_margin_first_share", 1.0, "[0, 1)"),
        ("space_margin_first_share", -0.1, "[0, 1)"),
    ],
)
def test_a_margin_out_of_range_is_a_config_error(field, value, valid):
    with pytest.raises(ConfigError) as err:
        SearchConfig(**{field: value})
    assert f"search.{field}" in str(err.value) and valid in str(err.value)


@pytest.mark.parametrize(
    "text, named, valid",
    [
        ("{search: {space_torque_fraction: 1.5}}", "search.space_torque_fraction = 1.5", "(0, 1]"),
        ("{search: {space_stance_margin: sometimes}}", "search.space_stance_margin = 'sometimes'", ""),
        ("{search: {space_margin_first_share: 1.5}}", "search.space_margin_first_share = 1.5", ""),
        *(
            (
                f"{{search: {{space_stance_fallback_safety: {v}}}}}",
                f"search.space_stance_fallback_safety = {v}",
                "(0, 1]",
            )
            for v in (0.0, 1.2, -0.5)
        ),
    ],
)
def test_a_margin_out_of_range_exits_2_before_any_search(tmp_path, capsys, text, named, valid):
    out = tmp_path / "plan"
    argv = ["plan", "--hand", "fingerpro4", "--goal-rpy", "0", "0", "0.5", "--out", str(out)]
    assert main([*argv, "--config-text", text]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0] and valid in err[0], err
    assert not out.exists()
