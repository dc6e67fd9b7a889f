"""The heaviest object the hand carries (trajectotree.search.payload): the block LP against one LP
per grasp built from Drake's own Jacobians and gravity forces, the bounds the limits must obey,
and the objects the tests plan with all carried."""

import math

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from scipy.optimize import linprog

from trajectotree.config import ObjectConfig, SceneConfig, SearchConfig
from trajectotree.scene.plant import build_scene
from trajectotree.search.initial_grasp import initial_grasp_candidates, stance_fingers
from trajectotree.search.payload import payload
from trajectotree.search.reach import Reachability

TRIANGLE = ((0.07, -0.040415), (0.0, 0.080829), (-0.07, -0.040415))  # tests/cli/test_polygon_cli.py
QUAD = ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04))  # tests/figures/test_figures.py


def heaviest_by_drake(scene, search, arclengths, fingers, cap: float) -> float:
    """N, one dense LP for one contact set: the contact points' Jacobians on link 2 and the
    gravity forces from the plant (not the closed forms payload uses)."""
    plant, context = scene.plant, scene.plant.CreateDefaultContext()
    pose = np.asarray(scene.config.initial_pose, dtype=float)
    reach = Reachability(scene)
    q = np.concatenate([reach.closed_form_many(pose, i, [s])[0] for i, s in enumerate(arclengths)])
    plant.SetPositions(context, scene.positions(pose, q))
    tau_g = plant.CalcGravityGeneralizedForces(context)[scene.hand_v_indices]
    mu = search.friction_safety * scene.config.mu
    c, s = math.cos(pose[2]), math.sin(pose[2])
    R = np.array([[c, -s], [s, c]])
    n = 2 * len(fingers) + 1
    A_eq, A_ub, b_ub = np.zeros((3, n)), [], []
    A_eq[1, -1] = -1.0
    for a, i in enumerate(fingers):
        p_BC, n_B = scene.config.shape.point(arclengths[i])
        t_B = np.array([-n_B[1], n_B[0]])
        p_WC = pose[:2] + R @ p_BC
        link = plant.GetBodyByName(f"finger{i}_link2", scene.hand)
        p_LC = link.body_frame().CalcPoseInWorld(context).inverse() @ np.array([*p_WC, 0.0])
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, link.body_frame(), p_LC, plant.world_frame(), plant.world_frame()
        )[:2, scene.hand_v_indices[2 * i : 2 * i + 2]]
        for e, sign in enumerate((1.0, -1.0)):
            f = R @ (-n_B + sign * mu * t_B)
            A_eq[:2, 2 * a + e] = f
            A_eq[2, 2 * a + e] = (p_WC[0] - pose[0]) * f[1] - (p_WC[1] - pose[1]) * f[0]
        tau_max = scene.fingers[i].tau_max
        for j in range(2):
            row = np.zeros(n)
            row[2 * a : 2 * a + 2] = [J[:, j] @ (R @ (-n_B + mu * t_B)), J[:, j] @ (R @ (-n_B - mu * t_B))]
            A_ub += [row, -row]
            b_ub += [tau_max[j] + tau_g[2 * i + j], tau_max[j] - tau_g[2 * i + j]]
    if cap:
        A_ub.append(np.r_[np.ones(n - 1), 0.0])
        b_ub.append(cap)
    cost = np.zeros(n)
    cost[-1] = -1.0
    result = linprog(cost, A_ub=np.array(A_ub), b_ub=b_ub, A_eq=A_eq, b_eq=np.zeros(3), bounds=(0, None))
    assert result.status == 0
    return result.x[-1]


@pytest.mark.parametrize("scene_config", [SceneConfig(), SceneConfig(object=ObjectConfig(vertices=QUAD))])
def test_the_block_lp_matches_one_drake_lp_per_grasp(scene_config):
    scene, search = build_scene(scene_config), SearchConfig()
    grasps = initial_grasp_candidates(scene, search)
    first = grasps.candidates[:3]
    g = scene_config.gravity
    hold = max(heaviest_by_drake(scene, search, c.arclengths, range(4), 0.0) for c in first) / g
    switch = (
        max(
            heaviest_by_drake(
                scene, search, c.arclengths, stance_fingers(scene.num_fingers)[i], search.max_stance_force
            )
            for c in first
            for i in range(4)
            if c.stance_required_mu[i] < grasps.mu_plan
        )
        / g
    )
    limits = payload(scene, search, grasps, first=3)
    assert limits.grasps == 3
    assert limits.hold_kg == pytest.approx(hold, rel=1e-6)
    assert limits.switch_kg == pytest.approx(switch, rel=1e-6)


_LIMITS = {}


def limits_of(scene_config: SceneConfig):
    """(scene, grasps, payload) of scene_config's object at the default search settings, computed once
    for the tests below (the box's by two of them)."""
    if scene_config not in _LIMITS:
        scene, search = build_scene(scene_config), SearchConfig()
        grasps = initial_grasp_candidates(scene, search)
        _LIMITS[scene_config] = scene, grasps, payload(scene, search)  # it ranks the grasps itself
    return _LIMITS[scene_config]


@pytest.mark.parametrize(
    "scene_config",
    [
        SceneConfig(),
        SceneConfig(box_width=0.15),
        SceneConfig(object=ObjectConfig(vertices=TRIANGLE)),
        SceneConfig(object=ObjectConfig(vertices=QUAD), initial_pose=(0.01, 0.02, 0.3)),
    ],
)
def test_the_limits_carry_the_tested_objects_and_obey_their_bounds(scene_config):
    """Three fingers carry no more than four; the cap bounds the weight by sum |f| <= sqrt(1 + mu^2)
    sum lambda_n; without the cap the torques alone bound it, higher."""
    search = SearchConfig()
    scene, grasps, limits = limits_of(scene_config)
    mu = grasps.mu_plan
    assert limits.grasps == len(grasps.candidates) and limits.tau_max == 1.0
    assert scene_config.box_mass < limits.switch_kg <= limits.hold_kg + 1e-9
    assert limits.switch_kg <= search.max_stance_force * math.sqrt(1 + mu * mu) / scene_config.gravity + 1e-9
    uncapped = payload(scene, SearchConfig(max_stance_force=0.0), grasps)
    assert uncapped.hold_kg == pytest.approx(limits.hold_kg)
    assert limits.switch_kg <= uncapped.switch_kg + 1e-9 and uncapped.switch_kg <= uncapped.hold_kg + 1e-9
    quick = payload(scene, search, grasps, first=1)
    assert quick.hold_kg <= limits.hold_kg + 1e-9 and quick.switch_kg <= limits.switch_kg + 1e-9


def test_the_box_limits():
    """The numbers the CLI states (README): 3.22 kg held, 1.01 kg while a finger switches, set by
    search.max_stance_force (a finger straight below the box pushes 10 N up, no torque on it)."""
    _, _, limits = limits_of(SceneConfig())
    assert limits.hold_kg == pytest.approx(3.2262, abs=1e-3)
    assert limits.switch_kg == pytest.approx(10.0 / 9.81, abs=1e-6)


def test_a_given_initial_grasp_is_the_only_one():
    search = SearchConfig(initial_arclengths=(0.52, 0.18, 0.20, 0.50))
    limits = payload(build_scene(), search)
    assert limits.grasps == 1
    assert limits.hold_kg == pytest.approx(
        heaviest_by_drake(build_scene(), search, search.initial_arclengths, range(4), 0.0) / 9.81, rel=1e-6
    )
