"""The search in space moves the finger rolled furthest since it landed first (issue 37, branch rows3d): a node's
switching children come in the order of their fingers' rolls. Axis 19 of the 23 axis-aligned goals, which by push
capacity alone found no plan within the default 30 s budget, finds one (slow; axis 18 likewise, 15 s of search:
docs/measurements.md)."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, mu_plan
from trajectotree.experiments.sweep import axis_aligned_goals
from trajectotree.scene.spatial import build_space_scene
from trajectotree.search.space_tree import _SpaceSearch
from trajectotree.search.tree import SearchClock


@pytest.fixture(scope="module")
def setting():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    return scene, config.search, mu_plan(config.scene, config.search)


def _switch_order(search, node, rolled) -> list[int]:
    """The fingers in the order `search` proposes to move them from `node` with the rolls `rolled` (F, 3)."""
    children = search.neighbors(dataclasses.replace(node, rolled=rolled))
    still = [i for i, c in enumerate(children) if c.finger is None]
    assert still == list(range(len(still)))  # no switch first (where the stance holds), as before
    fingers = [c.finger for c in children if c.finger is not None]
    return [f for i, f in enumerate(fingers) if f not in fingers[:i]]  # each finger's first appearance


@pytest.mark.slow  # axis 19's search first, ~3 s of CPU
def test_the_finger_rolled_furthest_moves_first(setting):
    scene, search_config, mu = setting
    assert search_config.time_budget_s == 30.0 and search_config.budget_clock == "cpu"
    search = _SpaceSearch(scene, axis_aligned_goals()[19], search_config, mu)
    leaf, why = search.run(search.roots()[0], SearchClock.start(search_config), search_config)
    assert leaf is not None, why  # within the default budget (none found before the roll order)
    path = [leaf.parent]  # the nodes before the goal's, which have children
    while path[-1].parent is not None:
        path.append(path[-1].parent)
    root = next(n for n in path if len(_switch_order(search, n, n.rolled)) >= 2)  # a node two fingers may leave
    # m along x in B, a fraction of a mm (no stance rolls off its face for it): finger 1 furthest, then 3, 2, 0
    rolled = np.zeros((scene.num_fingers, 3))
    rolled[:, 0] = [0.0001, 0.0004, 0.0002, 0.0003]
    order = _switch_order(search, root, rolled)
    assert len(order) >= 2 and np.all(np.diff(rolled[order, 0]) < 0), order
    flipped = np.zeros_like(rolled)
    flipped[:, 0] = 0.0005 - rolled[:, 0]  # the rolls' order reversed: so is the fingers'
    again = _switch_order(search, root, flipped)
    assert again == order[::-1] and np.all(np.diff(flipped[again, 0]) < 0), again
