"""The two controllers. Eq. 20 (ImpedanceController): closed-form checks of its torques
and the simulated static hold it must achieve (and that fails without it). The grasp
controller: its QP and schedule against closed forms, a three-finger static hold, a
push it recovers from, and a slow in-grasp rotation that both controllers track."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, ControllerGains, ImpedanceGains, with_values
from trajectotree.config.executor import Executor
from trajectotree.execution.impedance import ImpedanceController
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import simulate_reference
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.plant import NUM_FINGERS, build_scene

# Two fingers under the box and two above, 4 cm in from the corners.
HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def closed_form_gravity_compensation(finger, q, g):
    """dV/dq of one two-link finger in gravity -y: the torques that hold it still."""
    a1, a12 = finger.psi + q[0], finger.psi + q[0] + q[1]
    (m1, m2), (c1, c2) = finger.masses, finger.coms
    return g * np.array(
        [m1 * c1 * np.cos(a1) + m2 * (finger.l1 * np.cos(a1) + c2 * np.cos(a12)), m2 * c2 * np.cos(a12)]
    )


def test_actuation_is_eq20_in_closed_form(scene):
    gains = ControllerGains(impedance=ImpedanceGains(kp=150.0, kv=7.0))
    controller = ImpedanceController(scene.config, gains)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, v = rng.uniform(0.2, 1.4, 8), rng.uniform(-1.0, 1.0, 8)
        p_ref, v_ref, f_ref = (rng.uniform(-0.5, 0.5, (NUM_FINGERS, 2)) for _ in range(3))
        tau = controller.compute_actuation(np.r_[q, v], p_ref, v_ref, f_ref)
        for i, finger in enumerate(scene.fingers):
            q_i, v_i = q[2 * i : 2 * i + 2], v[2 * i : 2 * i + 2]
            J = finger.jacobian(q_i)
            F = (
                gains.impedance.kp * (p_ref[i] - finger.fingertip(q_i))
                + gains.impedance.kv * (v_ref[i] - J @ v_i)
                + f_ref[i]
            )
            expected = J.T @ F + closed_form_gravity_compensation(finger, q_i, scene.config.gravity)
            np.testing.assert_allclose(tau[2 * i : 2 * i + 2], expected, atol=1e-9)


def test_controller_ports_are_named(scene):
    controller = ImpedanceController(scene.config, ControllerGains())
    names = [controller.get_input_port(i).get_name() for i in range(controller.num_input_ports())]
    assert names == ["hand_state", "p_WF_ref", "v_WF_ref", "f_W_ref"]
    assert controller.get_output_port().get_name() == "actuation"
    assert controller.get_output_port().size() == 8


@pytest.fixture(scope="module")
def hold_reference(scene):
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=2.0)
    assert reference is not None
    return reference


@pytest.fixture(scope="module")
def hold_config():
    config = Config()
    return dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))


def test_controller_holds_the_box_for_two_seconds(hold_reference, hold_config):
    result = simulate_reference(hold_reference, hold_config, executor=Executor.PAPER)
    assert result.t[-1] == pytest.approx(2.0)
    position_error = np.linalg.norm(result.x[:, :2] - hold_reference.x[0, :2], axis=1)
    assert position_error.max() < 5e-3
    assert np.abs(result.x[:, 2] - hold_reference.x[0, 2]).max() < 0.05
    assert not result.dropped and result.drop_time_s is None


def test_without_the_controller_the_box_falls(hold_reference, hold_config):
    result = simulate_reference(hold_reference, hold_config, executor=Executor.NONE)
    assert result.dropped
    assert result.drop_time_s < 0.5
    assert result.x[-1, 1] < hold_reference.x[0, 1] - hold_config.sim.drop_distance  # it fell (gravity -y)


def in_grasp_rotation(scene, angle: float, duration: float, knots: int = 21):
    """A quasi-static reference that turns the grasped box by `angle` about its centre:
    the static hold at every knot (IK, balanced forces), fingertip velocities by
    finite differences."""
    from trajectotree.execution.reference import Reference

    times = np.linspace(0.0, duration, knots)
    holds = [
        static_hold_reference(
            scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=duration, pose=(0.0, 0.0, angle * t / duration)
        )
        for t in times
    ]
    assert all(h is not None for h in holds)
    p_WF = np.stack([h.p_WF[0] for h in holds])
    return Reference(
        t=times,
        x=np.stack([h.x[0] for h in holds]),
        q=np.stack([h.q[0] for h in holds]),
        p_WF=p_WF,
        v_WF=np.gradient(p_WF, times, axis=0),
        f_W=np.stack([h.f_W[0] for h in holds]),
    )


@pytest.mark.parametrize("controller", ["paper", "grasp"])
@pytest.mark.slow
def test_controller_tracks_a_slow_in_grasp_rotation(scene, hold_config, controller):
    reference = in_grasp_rotation(scene, 0.25, 2.0)
    result = simulate_reference(reference, hold_config, executor=Executor(controller))
    assert not result.dropped and result.controller == controller
    assert result.x[-1, 2] == pytest.approx(0.25, abs=0.03)
    assert result.mae_theta < 0.03 and result.mae_x < 3e-3 and result.mae_y < 3e-3


# --- the object-level grasp controller ----------------------------------------------------------


def grasp_config(settle_time: float = 0.0) -> Config:
    config = Config()
    return dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=settle_time))


@pytest.fixture(scope="module")
def three_finger_hold(scene):
    """Fingers 1-3 hold the box; finger 0 waits 1 cm below the bottom face."""
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=2.0, lifted=0)
    assert reference is not None
    np.testing.assert_allclose(reference.f_W[:, 0], 0.0, atol=1e-9)
    return reference


def test_grasp_controller_ports_are_named(scene, three_finger_hold):
    from trajectotree.execution.control import GraspController
    from trajectotree.execution.reference import grasp_schedule

    gains = ControllerGains()
    schedule = grasp_schedule(
        three_finger_hold,
        shape=ConvexPolygon.box(0.2, 0.1),
        tip_radius=scene.tip_radius,
        period=0.002,
        duration=2.0,
        ramp_time=0.1,
        swing_lift=0.008,
        contact_distance=1e-3,
    )
    controller = GraspController(scene, gains, mu=0.49)
    names = [controller.get_input_port(i).get_name() for i in range(controller.num_input_ports())]
    assert names == ["box_state", "hand_state", "plan"]
    assert controller.get_output_port().get_name() == "actuation" and controller.get_output_port().size() == 8
    # the lifted finger is out of contact for the whole hold: no planned force, no force budget
    np.testing.assert_array_equal(schedule.force_scale[:, 0], 0.0)
    np.testing.assert_array_equal(schedule.force_scale[:, 1:], 1.0)
    assert len(schedule.X) == 1001


def test_grasp_controller_holds_a_three_finger_grasp_for_two_seconds(three_finger_hold):
    result = simulate_reference(three_finger_hold, grasp_config(), executor=Executor.GRASP)
    assert result.controller == "grasp" and result.t[-1] == pytest.approx(2.0)
    position_error = np.linalg.norm(result.x[:, :2] - three_finger_hold.x[0, :2], axis=1)
    assert position_error.max() < 1e-3
    assert np.abs(result.x[:, 2] - three_finger_hold.x[0, 2]).max() < 0.01
    assert not result.dropped
    np.testing.assert_array_equal(result.f_W[:, 0], 0.0)  # the lifted finger never touches the box


@pytest.mark.slow
def test_grasp_controller_recovers_from_a_push(three_finger_hold):
    """0.2 N sideways (40 % of the box's weight) for 0.2 s: the box is knocked away and comes back."""
    from trajectotree.execution.world import Conditions, Push

    push = Push(force=(0.2, 0.0), time_s=0.5, duration_s=0.2)
    result = simulate_reference(
        three_finger_hold, grasp_config(), executor=Executor.GRASP, conditions=Conditions(push=push)
    )
    error = np.linalg.norm(result.x[:, :2] - three_finger_hold.x[0, :2], axis=1)
    during = (result.t > 0.5) & (result.t < 0.8)
    assert error[during].max() > 1e-3  # the push moved the box
    assert error[result.t > 1.5].max() < 5e-4  # and the controller brought it back
    assert np.abs(result.x[result.t > 1.5, 2]).max() < 0.01
    assert not result.dropped
    assert result.conditions["push"] == {"force": [0.2, 0.0], "time_s": 0.5, "duration_s": 0.2}
    # without the push the same run stays put (so the excursion above is the push's)
    still = simulate_reference(three_finger_hold, grasp_config(), executor=Executor.GRASP)
    assert np.linalg.norm(still.x[:, :2] - three_finger_hold.x[0, :2], axis=1).max() < 1e-3


def test_grasp_force_qp_meets_a_feasible_wrench_within_the_cones():
    """Four fingers on the faces of an axis-aligned box; finger 0 has no force budget."""
    from trajectotree.execution.control import GraspForceQp

    mu = 0.5
    qp = GraspForceQp(mu, torque_length=0.1, wrench_weight=1e4, num_fingers=4)
    n_W = np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]])
    r_W = np.array([[0.06, -0.05], [0.06, 0.05], [-0.06, 0.05], [-0.06, -0.05]])
    t_W = np.stack([-n_W[:, 1], n_W[:, 0]], axis=1)
    G = np.zeros((3, 8))
    G[:2, 0::2], G[:2, 1::2] = -n_W.T, t_W.T
    G[2, 0::2] = r_W[:, 0] * -n_W[:, 1] + r_W[:, 1] * n_W[:, 0]
    G[2, 1::2] = r_W[:, 0] * t_W[:, 1] - r_W[:, 1] * t_W[:, 0]
    wrench = np.array([0.05, 0.5, 0.002])
    lo, hi = np.array([0.0, 0.1, 0.1, 0.1]), np.array([0.0, 5.0, 5.0, 5.0])
    lam = qp.solve(G, wrench, np.zeros((4, 2)), lo, hi)
    np.testing.assert_allclose(lam[0], 0.0, atol=1e-6)
    assert np.all(lam[1:, 0] >= 0.1 - 1e-6) and np.all(lam[:, 0] <= hi + 1e-6)
    assert np.all(np.abs(lam[:, 1]) <= mu * lam[:, 0] + 1e-6)
    np.testing.assert_allclose(G @ lam.ravel(), wrench, atol=1e-3)


def test_a_rolled_two_finger_pinch_needs_the_controllers_friction_cone():
    """Goal 0.861's stance while finger 3 swings, at theta 0.63 with the contacts measured in
    simulation: finger 2 rolled 6.6 mm along the top face, so the pinch line of fingers 0 and 2
    leans 25 deg off the normal (needs mu 0.47; 0.40 at the planned points). With the plan's cone
    (0.49) the QP squeezes hard and still misses the weight; with the controller's default cone
    (max(search 0.7, controller 0.8) x 0.7 = 0.56) it holds the box with less than half of that."""
    from trajectotree.execution.control import GraspForceQp
    from trajectotree.geometry import rotation_2d
    from trajectotree.scene.statics import perp

    config = Config()
    R = rotation_2d(0.63)
    n_W = np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]]) @ R.T
    r_W = np.array([[-0.0402, -0.05], [0.0395, 0.05], [0.0066, 0.05], [-0.0217, -0.05]]) @ R.T
    t_W = perp(n_W)
    G = np.zeros((3, 8))
    G[:2, 0::2], G[:2, 1::2] = -n_W.T, t_W.T
    G[2, 0::2] = r_W[:, 0] * -n_W[:, 1] + r_W[:, 1] * n_W[:, 0]
    G[2, 1::2] = r_W[:, 0] * t_W[:, 1] - r_W[:, 1] * t_W[:, 0]
    weight = np.array([0.0, config.scene.box_mass * config.scene.gravity, 0.0])
    lo, hi = np.array([0.1, 0.1, 0.1, 0.0]), np.array([8.0, 8.0, 8.0, 0.0])  # finger 3 lifted

    def solve(mu):
        lam = GraspForceQp(mu, torque_length=0.112, wrench_weight=1e4, num_fingers=4).solve(
            G, weight, np.zeros((4, 2)), lo, hi
        )
        return lam, np.linalg.norm((G @ lam.ravel() - weight)[:2])

    mu_control = max(config.search.friction_safety, config.controller.grasp.friction_safety) * config.scene.mu
    assert mu_control == pytest.approx(0.56)
    (lam_plan, miss_plan), (lam, miss) = solve(config.search.friction_safety * config.scene.mu), solve(mu_control)
    assert lam_plan[0, 0] > 3.5 and miss_plan > 0.015
    assert lam[0, 0] < 0.65 * lam_plan[0, 0] and miss < 0.3 * miss_plan


def test_schedule_ramps_a_switching_finger_and_follows_a_cubic():
    from trajectotree.execution.reference import hermite, swing_intervals, swing_profile

    t = np.linspace(0.0, 1.0, 11)
    in_contact = np.array([1, 1, 1, 0, 0, 0, 1, 1, 1, 1, 1], dtype=bool)
    intervals = swing_intervals(t, in_contact)
    assert intervals == [(pytest.approx(0.2), pytest.approx(0.6))]
    times = np.array([0.0, 0.2, 0.25, 0.3, 0.4, 0.5, 0.55, 0.6, 0.8])
    scale, phase = swing_profile(times, intervals, ramp_time=0.1)
    # 1 up to lift-off, 0 from one ramp after it to one ramp before landing, 1 from landing on
    np.testing.assert_allclose(scale, [1.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(phase[4], 0.5)
    assert np.isnan(phase[0]) and np.isnan(phase[-1])
    # a cubic is reproduced exactly (value, rate, acceleration) from its knot values and rates
    assert swing_profile(np.array([0.4]), [(0.35, 0.45)], ramp_time=0.1)[0] == pytest.approx(0.0)  # short swing

    def f(s):
        return 2 * s**3 - s**2 + 0.5 * s

    value, rate, accel = hermite(t, f(t)[:, None], (6 * t**2 - 2 * t + 0.5)[:, None], times)
    np.testing.assert_allclose(value[:, 0], f(times), atol=1e-12)
    np.testing.assert_allclose(rate[:, 0], 6 * times**2 - 2 * times + 0.5, atol=1e-10)
    np.testing.assert_allclose(accel[:, 0], 12 * times - 2, atol=1e-8)


def test_vectorized_hand_kinematics_match_each_finger(scene):
    from trajectotree.execution.fingers import HandKinematics

    kinematics = HandKinematics(scene.fingers, scene.config.gravity)
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = rng.uniform(-1.0, 1.5, 8)
        p, J, g = kinematics(q)
        for i, finger in enumerate(scene.fingers):
            q_i = q[2 * i : 2 * i + 2]
            np.testing.assert_allclose(p[i], finger.fingertip(q_i), atol=1e-12)
            np.testing.assert_allclose(J[i], finger.jacobian(q_i), atol=1e-12)
            np.testing.assert_allclose(
                g[i], closed_form_gravity_compensation(finger, q_i, scene.config.gravity), atol=1e-12
            )


def test_grasp_controller_pushes_along_the_normal_where_a_disc_is_touched_now():
    """A disc turned 0.1 rad under fingertips that stayed where the plan put them: every normal of
    a disc passes through its centre, so the normals at the touched points are still the planned
    ones in W (radial, up to the polygonized outline's facets), and the QP must use those. The
    planned contact normals turned with the disc lean 0.1 rad off, and a QP built on them credits
    the squeeze with a torque that a disc's normals cannot make."""
    from trajectotree.config import ObjectConfig, SceneConfig
    from trajectotree.execution.control import GraspController
    from trajectotree.execution.reference import grasp_schedule

    disc = build_scene(SceneConfig(object=ObjectConfig(circle_radius=0.06)))
    shape = disc.config.shape
    angles = np.radians([-60.0, 60.0, 120.0, -120.0])  # a finger on each quarter, nearest its base
    arclengths = [shape.arclength(0.06 * np.array([np.cos(a), np.sin(a)])) for a in angles]
    reference = static_hold_reference(disc, arclengths, min_normal_force=0.5, duration=1.0)
    assert reference is not None
    gains = ControllerGains()
    schedule = grasp_schedule(
        reference,
        shape=shape,
        tip_radius=disc.tip_radius,
        period=1.0 / gains.rate_hz,
        duration=1.0,
        ramp_time=gains.grasp.ramp_time,
        swing_lift=gains.grasp.swing_lift,
        contact_distance=gains.grasp.contact_distance,
    )
    controller = GraspController(disc, gains, mu=0.56)
    p_WF = reference.p_WF[0]
    radial = p_WF / np.linalg.norm(p_WF, axis=1, keepdims=True)  # the disc's centre at the origin
    for turn in (0.0, 0.1):
        box_state = np.array([0.0, 0.0, turn, 0.0, 0.0, 0.0])
        f_W, n_W = controller.finger_forces(schedule, 0, box_state, p_WF, controller.planned)
        lean = np.arcsin(
            radial[:, 0] * n_W[:, 1] - radial[:, 1] * n_W[:, 0]
        )  # rad; the outline's facets (1 cm at most) leave ~0.01
        assert np.all(np.abs(lean) < 0.02), (turn, lean)
        pushes = -np.sum(f_W * n_W, axis=1)
        assert np.all(pushes >= gains.grasp.min_normal_force - 1e-6)


@pytest.mark.parametrize("hand", ["planar_hand", "drake_planar_gripper"])
def test_hand_dynamics_match_drakes_mass_matrix_and_bias_term(hand):
    """The grasp controller's closed-form link dynamics (gains.grasp.hand_dynamics) against the plant's own:
    each finger's mass matrix is the diagonal block of CalcMassMatrix, and its Coriolis torques the
    bias term's rows (the joint damping is returned with them, at the model's coefficients)."""
    from trajectotree.config import SceneConfig
    from trajectotree.execution.fingers import HandKinematics

    scene = build_scene(SceneConfig(hand=hand))
    plant, context = scene.plant, scene.plant.CreateDefaultContext()
    kinematics = HandKinematics(scene.fingers, scene.config.gravity)
    rng = np.random.default_rng(2)
    index = np.asarray(scene.hand_v_indices)
    for _ in range(3):
        q, v = rng.uniform(-1.0, 1.5, scene.num_hand_joints), rng.uniform(-2.0, 2.0, scene.num_hand_joints)
        plant.SetPositions(context, scene.hand, q)
        plant.SetVelocities(context, scene.hand, v)
        M_drake = plant.CalcMassMatrix(context)[np.ix_(index, index)]
        bias_drake = plant.CalcBiasTerm(context)[index]
        M, motion = kinematics.dynamics(q, v)
        damping = np.array([f.damping for f in scene.fingers])
        for i in range(scene.num_fingers):
            block = slice(2 * i, 2 * i + 2)
            np.testing.assert_allclose(M[i], M_drake[block, block], rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(M_drake[block, : 2 * i], 0.0, atol=1e-12)  # no coupling between fingers
            np.testing.assert_allclose(motion[i] - damping[i] * v[block], bias_drake[block], rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(
            damping.ravel(),
            [
                plant.get_joint(j).default_damping_vector()[0]
                for j in plant.GetJointIndices(scene.hand)
                if plant.get_joint(j).num_velocities() == 1
            ],
        )


def schedule_of(reference, scene, gains: ControllerGains, duration: float):
    """The GraspSchedule the controller of `gains` tracks for `reference` on the 0.2 x 0.1 m box."""
    from trajectotree.execution.reference import grasp_schedule

    return grasp_schedule(
        reference,
        shape=ConvexPolygon.box(0.2, 0.1),
        tip_radius=scene.tip_radius,
        period=1.0 / gains.rate_hz,
        duration=duration,
        ramp_time=gains.grasp.ramp_time,
        swing_lift=gains.grasp.swing_lift,
        contact_distance=gains.grasp.contact_distance,
    )


def test_landing_reflex_runs_a_swing_ahead_to_its_landing_and_waits_there(scene):
    """A finger that swings while a push is on (or the friction estimate has fallen) follows its
    planned swing land_speedup x as fast up to its next planned landing and holds there until
    the plan gets there; without a trigger every finger follows the plan's sample."""
    from trajectotree.execution.reference import Reference
    from trajectotree.execution.reflexes import LandingReflex

    held = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=1.0)
    lifted = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=1.0, lifted=0)
    # finger 0 holds at t = 0 and 0.5 s, is lifted at 1.0 s and lands again at 1.5 s
    order = [0, 0, 1, 0, 0]
    refs = [held, lifted]
    reference = Reference(
        t=np.array([0.0, 0.5, 1.0, 1.5, 2.0]),
        **{name: np.stack([getattr(refs[k], name)[0] for k in order]) for name in ("x", "q", "p_WF", "v_WF", "f_W")},
    )
    gains = ControllerGains()
    schedule = schedule_of(reference, scene, gains, 2.0)
    controller = LandingReflex(scene, gains)
    landing = int(np.argmax(schedule.force_scale[schedule.index(1.0) :, 0] >= 1.0)) + schedule.index(1.0)
    assert schedule.index(1.4) < landing <= schedule.index(1.5)
    calm, pushed = controller.landing_triggered(0.7, 0.0, 0.7), controller.landing_triggered(0.7, 1.0, 0.7)
    slipped = controller.landing_triggered(0.4, 0.0, 0.7)
    assert not calm and pushed and slipped
    n = schedule.index(1.0)  # the swing's core: finger 0 has no force budget
    assert schedule.force_scale[n, 0] == 0.0
    np.testing.assert_array_equal(controller.landing_clocks(schedule, n, np.full(4, n - 1), calm), [n] * 4)
    speedup = int(gains.landing_reflex.speedup)
    for estimates in (pushed, slipped):
        clocks = controller.landing_clocks(schedule, n, np.full(4, n - 1), estimates)
        np.testing.assert_array_equal(clocks, [n - 1 + speedup, n, n, n])
    # once begun, the landing goes on without the trigger, stops at the landing and waits there
    clocks, steps = np.full(4, n - 1), 0
    for k in range(n, landing + 5):
        clocks = controller.landing_clocks(schedule, k, clocks, pushed if k == n else calm)
        steps += 1
        if clocks[0] == landing:
            break
    # land_speedup x as fast, the last land_approach_time land_approach_speedup x
    approach = round(gains.landing_reflex.approach_time * gains.rate_hz)
    slow = int(gains.landing_reflex.approach_speedup)
    assert clocks[0] == landing and steps <= (landing - n - approach) / (speedup - 1) + approach / (slow - 1) + 2
    # a fingertip that lags its target holds its sample
    lagging = controller.landing_clocks(
        schedule, n, np.full(4, n - 1), pushed, lag=np.full(4, 2 * gains.landing_reflex.lag)
    )
    np.testing.assert_array_equal(lagging, [n] * 4)
    assert controller.landing_clocks(schedule, n + steps + 1, clocks, calm)[0] == landing
    assert controller.landing_clocks(schedule, landing + 3, clocks, calm)[0] == landing + 3
    # land_speedup 1: no reflex
    off = LandingReflex(scene, with_values(gains, {"landing_reflex.speedup": 1.0})).landing_clocks(
        schedule, n, np.full(4, n - 1), pushed
    )
    np.testing.assert_array_equal(off, [n] * 4)


@pytest.mark.parametrize("tau", [0.1, 0.0])
def test_closed_loop_cones_follow_the_friction_estimate_over_their_time_constant(scene, tau):
    """When the estimate falls from 0.7 to 0.3 the QP's cone friction falls as a first-order lag
    (about 63 % of the way after cone_time_constant, never past the estimate); 0: at once."""
    from trajectotree.execution.reflexes import ConeFriction

    gains = with_values(ControllerGains(), {"grasp.cone_time_constant": tau})
    controller = ConeFriction(gains, mu_assumed=0.7)
    cone, cones = 0.7, []
    for _ in range(int(round(0.1 * gains.rate_hz))):  # 0.1 s of control periods
        cone = controller.cone_friction(cone, 0.3)
        cones.append(cone)
    assert np.all(np.diff(cones) <= 0.0) and min(cones) >= 0.3
    if tau > 0:
        assert cones[0] == pytest.approx(0.7 - 0.4 / (gains.rate_hz * tau))
        assert cones[-1] == pytest.approx(0.3 + 0.4 * np.exp(-0.1 / tau), abs=0.005)
    else:
        assert cones == [0.3] * len(cones)
