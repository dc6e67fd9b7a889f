"""A three-finger hand (Drake's planar gripper) in the search: while one finger switches the
other two hold the object, and their stance's friction is the exact two-contact closure
(grasp.required_mu_many at k = 2), checked against Nguyen's closed form for contacts on opposite
faces: the line between them must lie inside both friction cones, mu* = |tangential offset| /
distance between the faces."""

import numpy as np
import pytest

from trajectotree.config import SceneConfig, SearchConfig
from trajectotree.scene.hand import with_hand_object
from trajectotree.scene.plant import build_scene
from trajectotree.search.grasp import MU_CAP
from trajectotree.search.initial_grasp import RANKING_BISECTIONS, initial_grasp_candidates, stance_fingers
from trajectotree.search.workspace import rotation_range


@pytest.fixture(scope="module")
def brick_scene():
    return build_scene(SceneConfig(hand="drake_planar_gripper", box_width=0.1, box_height=0.1, box_mass=0.028))


def test_two_finger_stances_match_the_antipodal_closed_form(brick_scene):
    grasps = initial_grasp_candidates(brick_scene, SearchConfig())
    assert len(grasps) > 0 and grasps.arclengths.shape[1] == 3
    shape = brick_scene.config.shape
    checked = 0
    for arclengths, stance_mu in zip(grasps.arclengths, grasps.stance_mu):
        for i, (a, b) in enumerate(stance_fingers(3)):
            (p1, n1), (p2, n2) = shape.point(arclengths[a]), shape.point(arclengths[b])
            if not np.allclose(n1, -n2):  # adjacent faces: no antipodal closed form
                continue
            d = p2 - p1
            tangent = np.array([-n1[1], n1[0]])
            closed_form = abs(d @ tangent) / abs(d @ n1)
            assert stance_mu[i] == pytest.approx(closed_form, abs=2 * MU_CAP / 2**RANKING_BISECTIONS)
            checked += 1
    assert checked > 0
    free = grasps.stance_mu < grasps.mu_plan
    assert np.all(free.any(axis=1)) and np.array_equal(free.sum(axis=1), grasps.free_fingers)


@pytest.mark.slow  # ten contact searches, two of them without a plan (~5 s)
def test_the_gripper_turns_its_brick_in_place_only_so_far():
    """rotation_range on a coarse grid: the contact search turns Drake's brick (with_hand_object's)
    1.2 rad either way but not 1.5: each switch needs the other two fingers on opposite faces, and
    near a quarter turn no such pair is left while the fingers must still move on."""
    scene = build_scene(with_hand_object(SceneConfig(hand="drake_planar_gripper")))
    turns = rotation_range(scene, SearchConfig(), step=0.3, limit=1.5)
    assert (turns.ccw, turns.cw, turns.refused) == (pytest.approx(1.2), pytest.approx(1.2), (1.5, -1.5))
