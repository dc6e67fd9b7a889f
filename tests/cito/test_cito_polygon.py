"""CITO on a convex polygon that is not a box: a hand-made two-segment contact plan for the
equilateral triangle of side 0.14 m (the polygon gallery's first shape) whose switching finger moves
around a corner, planned with both formulations and checked against the physics check."""

import dataclasses
import math

import numpy as np
import pytest

from trajectotree.cito.guess import plan_guess
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program
from trajectotree.cito.transition import check_plan, transition_spec
from trajectotree.config import CitoConfig, Config, ConfigError, ObjectConfig, SceneConfig, SearchConfig, mu_plan
from trajectotree.contact_plan import ContactNode, ContactPlan
from trajectotree.geometry import box_to_world
from trajectotree.planning.planners import plan
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import build_scene

SIDE = 0.14
TRIANGLE = tuple(
    (SIDE / math.sqrt(3) * math.cos(a), SIDE / math.sqrt(3) * math.sin(a))
    for a in -math.pi / 2 + 2 * math.pi / 3 * np.arange(3)
)
CONFIG = Config(scene=SceneConfig(object=ObjectConfig(vertices=TRIANGLE)), search=SearchConfig(num_nodes=3))
GOAL = 0.3
# (pose theta, arclengths, switching finger) of each node: finger 2 moves from 0.32 m to 0.20 m of
# the 0.42 m boundary (round the corner at 0.28 m), then finger 1 from 0.16 m to 0.18 m.
NODES = ((0.0, (0.08, 0.16, 0.32, 0.40), None), (0.15, (0.08, 0.16, 0.20, 0.40), 2), (0.3, (0.08, 0.18, 0.20, 0.40), 1))


@pytest.fixture(scope="module")
def scene():
    return build_scene(CONFIG.scene)


@pytest.fixture(scope="module")
def contact_plan(scene) -> ContactPlan:
    """The nodes' grasps with the joint angles by closed-form IK (the search's)."""
    shape, hand, r = scene.config.shape, HandModel.from_scene(scene), scene.tip_radius
    nodes = []
    for theta, arclengths, switching in NODES:
        pose = np.array([0.0, 0.0, theta])
        p_BC, n_B = shape.points(np.array(arclengths))
        q = np.concatenate([hand.ik(i, box_to_world(pose, p_BC[i] + r * n_B[i])) for i in range(4)])
        nodes.append(
            ContactNode(
                object_pose=pose,
                q=q,
                arclengths=np.array(arclengths),
                p_BC=p_BC,
                n_B=n_B,
                switching_finger=switching,
                closure_margin=0.1,
            )
        )
    return ContactPlan(goal=GOAL, success=True, nodes=tuple(nodes), mu_plan=mu_plan(CONFIG.scene, CONFIG.search))


def test_the_plan_is_the_triangles_and_moves_a_finger_round_a_corner(scene, contact_plan):
    shape = scene.config.shape
    assert len(shape.vertices) == 3 and not shape.is_box
    check_plan(contact_plan, scene)
    corners = shape.corner_arclengths()
    assert np.any((corners > 0.20) & (corners < 0.32))  # finger 2 crosses a corner
    box = build_scene(SceneConfig())
    with pytest.raises(ConfigError, match="off the boundary"):  # the triangle's contacts are not the box's
        check_plan(contact_plan, box)


def test_the_plan_guess_follows_the_triangle(scene, contact_plan):
    """Pinned fingertips of the guess sit on their planned centres; the switching finger's stays
    off the triangle by at least the tip radius all the way round the corner."""
    config = CONFIG.cito
    spec = transition_spec(contact_plan, radius=scene.tip_radius, config=config)
    program = build_program(
        config, spec, BodyParams(scene, config.sdf_sharpness, mu=mu_plan(CONFIG.scene, CONFIG.search))
    )
    guess = plan_guess(program.rows, spec, contact_plan)
    kin = program.rows.kinematics(guess.stacked())
    np.testing.assert_allclose(np.linalg.norm(kin.e, axis=-1)[spec.pinned], 0.0, atol=1e-9)
    gap = scene.config.shape.signed_distances(kin.p_BF[~spec.pinned]) - scene.tip_radius
    assert gap.min() > 0.0


# The joint formulation's one program over both segments takes seconds: slow (the quick suite still builds
# and solves joint-formulation programs: tests/cito/test_cito_solve.py, and test_cli.py's unconverged plan).
@pytest.mark.parametrize("formulation", ["keyframes", pytest.param("joint", marks=pytest.mark.slow)])
def test_a_triangle_plan_is_physical(scene, contact_plan, formulation):
    config = dataclasses.replace(CONFIG, cito=dataclasses.replace(CitoConfig(), formulation=formulation))
    result = plan(
        scene=scene, goal=GOAL, method="trajectotree", config=config, contact_plan=contact_plan, segment_workers=1
    )
    assert result.success and result.physics_check.passed, result.status
    assert abs(result.trajectory.x[-1, 2] - GOAL) < math.radians(1.0)
    # the plan's object model is the triangle's: its inertia and its boundary
    assert result.physics_check.contact_point_off_surface_m < 1e-9
    if formulation == "keyframes":
        assert all(s["retries"] == 0 for s in result.segments)
    # The free finger really went round: somewhere between its contacts it faces another side.
    tips = result.trajectory.p_W_tip[:13, 2]
    x = result.trajectory.x[:13]
    shape = scene.config.shape
    faces = {
        int(
            np.argmax(
                shape.normals @ (np.array([[math.cos(t), math.sin(t)], [-math.sin(t), math.cos(t)]]) @ (p - xi[:2]))
                - shape.offsets
            )
        )
        for p, xi, t in zip(tips, x, x[:, 2])
    }
    assert len(faces) == 2
