"""The closed loop in space holds the node before a swing whose stance the measured friction cannot carry (issue 37,
friction 0.4): space_control.stance_holds against statics' closed form, and SpaceClosedLoopGraspController's
followed_time on a constructed swing of the search's initial grasp."""

import numpy as np
import pytest
from test_space_execution import _initial_grasp_hold

from trajectotree.config import Config
from trajectotree.execution.executor import control_friction
from trajectotree.execution.space_control import SpaceClosedLoopGraspController, SpaceReference, stance_holds
from trajectotree.execution.space_run import space_plan_in_effect
from trajectotree.scene.spatial import build_space_scene
from trajectotree.scene.statics import grasp_matrix_3d_W

WEIGHT = 0.92  # N, a 94 g cube's


def _pinch(push_cap: float):
    """Two fingertips pinching a 5 cm cube from its -x and +x faces, the weight along -z: (G, wrench, torque rows
    whose one row caps finger 0's push at push_cap N, as a motor would)."""
    G = grasp_matrix_3d_W(np.array([[-0.025, 0.0, 0.0], [0.025, 0.0, 0.0]]), np.array([[-1.0, 0, 0], [1.0, 0, 0]]))
    A = np.zeros((1, 6))
    A[0, 0] = 1.0  # finger 0's normal push
    return G, np.array([0.0, 0.0, WEIGHT, 0.0, 0.0, 0.0]), (A, np.array([-np.inf]), np.array([push_cap]))


@pytest.mark.parametrize("push_cap", [2.0, 1.5])
def test_a_pinch_holds_the_weight_from_the_friction_statics_gives(push_cap):
    """Each finger carries half the weight by friction, f_t = W / 2 <= mu f_n, and the pushes balance, f_n <= cap
    (the normal bound 2 N or the 'motor' row's cap): the pinch holds from mu = W / (2 cap) up, not below."""
    G, wrench, torque = _pinch(push_cap)
    lo, hi = np.full(2, 0.1), np.full(2, 2.0)
    need = WEIGHT / (2.0 * push_cap)
    assert stance_holds(G, wrench, lo, hi, torque, 1.01 * need)
    assert not stance_holds(G, wrench, lo, hi, torque, 0.99 * need)


@pytest.fixture(scope="module")
def swing():
    """The search's initial grasp held 1.5 s with finger 1 (which it does not load: fingers 0 and 2 pinch the
    cube) 1 cm off the cube along its centre's offset at 0.5 and 1.0 s: a swing from 0 to 1.5 s. The plan in effect
    and the closed-loop controller."""
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    held = _initial_grasp_hold(scene, 1.5)
    t = np.array([0.0, 0.5, 1.0, 1.5])
    knots = {name: np.stack([getattr(held, name)[0]] * 4) for name in ("x", "q", "f_W", "p_W_C", "p_W_tip")}
    assert np.allclose(knots["f_W"][:, 1], 0.0)
    out = knots["p_W_tip"][0, 1] - knots["x"][0, 4:]
    knots["p_W_tip"][1:3, 1] += 0.01 * out / np.linalg.norm(out)
    reference = SpaceReference(t=t, v=np.zeros((4, 6)), **knots)
    plan = space_plan_in_effect(reference, config, scene)
    controller = SpaceClosedLoopGraspController(scene, config.controller, mu=control_friction(config))
    return plan, controller


@pytest.mark.parametrize("mu_estimate, holds", [(0.7, False), (0.02, True)])
def test_a_swing_the_friction_estimate_cannot_carry_holds_its_node(swing, mu_estimate, holds):
    """At the first sample of finger 1's lift-off hold, the controller checks the three others' stance through the
    swing at the friction estimate: at the plan's 0.7 it follows the plan's time; at 0.02 the stance cannot carry
    the weight and it holds the sample before (its node, every finger loaded) from then on."""
    plan, controller = swing
    s = plan.schedule
    n = int(np.argmax(s.lifting[:, 1]))
    assert n > 0 and not s.lifting[n - 1, 1] and np.all(s.force_scale[n - 1] == 1.0)
    context = controller.CreateDefaultContext()
    controller.plan_port.FixValue(context, plan)
    for port, value in (
        (controller.friction_port, [mu_estimate]),
        (controller.mass_estimate_port, [controller._mass]),
        (controller.reflex_port, [0.0]),
        (controller.disturbance_port, np.zeros(3)),
    ):
        port.FixValue(context, np.asarray(value, dtype=float))
    followed = []
    for m in (n, n + 1):
        context.SetTime(m * s.period)
        state = context.get_discrete_state().Clone()
        followed.append(controller.followed_time(context, state))
        context.SetDiscreteState(state)
    expected = [(n - 1) * s.period] * 2 if holds else [n * s.period, (n + 1) * s.period]
    np.testing.assert_allclose(followed, expected)
