"""Round and blunt-cornered objects in the contact search: a disc, an ellipse and a 12-gon, whose
corners are too blunt for the right-angle corner margin to apply (geometry.corner_margins)."""

import math

import numpy as np
import pytest

from trajectotree.config import ObjectConfig, SceneConfig, SearchConfig
from trajectotree.geometry import box_to_world, rotation_2d
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.tree import find_contact_plan

TWELVE_GON = tuple(
    (0.065 * math.cos(2 * math.pi * (k + 0.5) / 12), 0.065 * math.sin(2 * math.pi * (k + 0.5) / 12)) for k in range(12)
)


@pytest.mark.parametrize(
    "outline, goal",
    [
        (ObjectConfig(circle_radius=0.06), -2.884),
        (ObjectConfig(ellipse_semi_axes=(0.08, 0.05)), 2.593),
        (ObjectConfig(vertices=TWELVE_GON), -3.038),
    ],
)
def test_round_objects_get_contact_plans_on_their_boundary(outline, goal):
    scene = build_scene(SceneConfig(object=outline))
    plan = find_contact_plan(scene, goal, SearchConfig())
    assert plan.success, plan.reason
    shape = scene.config.shape
    for node in plan.nodes:
        assert np.all(shape.corner_free(node.arclengths + 1e-12, scene.config.corner_margin))
        p_WF = scene.fingertip_positions(node.q)
        for i in range(NUM_FINGERS):
            if outline.circle_radius is not None:  # the disc's closed form: on the circle, normal radial
                r = np.linalg.norm(node.p_BC[i])
                n = len(shape.vertices)  # facets of the polygonized disc
                assert 0.06 * math.cos(math.pi / n) - 1e-12 <= r <= 0.06 + 1e-12
                assert np.arccos(min(1.0, node.n_B[i] @ node.p_BC[i] / r)) <= 1e-6  # the circle's normal
            target = box_to_world(node.object_pose, node.p_BC[i]) + scene.tip_radius * (
                rotation_2d(node.object_pose[2]) @ node.n_B[i]
            )
            np.testing.assert_allclose(p_WF[i], target, atol=1e-6)  # the joints put the tip on the contact
