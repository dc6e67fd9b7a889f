"""The impedance controller (eq. 20): closed-form checks of its torques, and the
simulated static hold it must achieve (and that fails without it)."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, ControllerGains
from trajectotree.control import ImpedanceController
from trajectotree.reference import static_hold_reference
from trajectotree.scene import NUM_FINGERS, build_scene
from trajectotree.simulate import simulate_reference

# Two fingers under the box and two above, 4 cm in from the corners.
HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def closed_form_gravity_compensation(finger, q, g):
    """dV/dq of one two-link finger in gravity -y: the torques that hold it still."""
    a1, a12 = finger.psi + q[0], finger.psi + q[0] + q[1]
    (m1, m2), (c1, c2) = finger.masses, finger.coms
    return g * np.array([m1 * c1 * np.cos(a1) + m2 * (finger.l1 * np.cos(a1) + c2 * np.cos(a12)),
                         m2 * c2 * np.cos(a12)])


def test_actuation_is_eq20_in_closed_form(scene):
    gains = ControllerGains(kp=150.0, kv=7.0)
    controller = ImpedanceController(scene.config, gains)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, v = rng.uniform(0.2, 1.4, 8), rng.uniform(-1.0, 1.0, 8)
        p_ref, v_ref, f_ref = (rng.uniform(-0.5, 0.5, (NUM_FINGERS, 2)) for _ in range(3))
        tau = controller.compute_actuation(np.r_[q, v], p_ref, v_ref, f_ref)
        for i, finger in enumerate(scene.fingers):
            q_i, v_i = q[2 * i:2 * i + 2], v[2 * i:2 * i + 2]
            J = finger.jacobian(q_i)
            F = gains.kp * (p_ref[i] - finger.fingertip(q_i)) + gains.kv * (v_ref[i] - J @ v_i) + f_ref[i]
            expected = J.T @ F + closed_form_gravity_compensation(finger, q_i, scene.config.gravity)
            np.testing.assert_allclose(tau[2 * i:2 * i + 2], expected, atol=1e-9)


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
    result = simulate_reference(hold_reference, hold_config)
    assert result.t[-1] == pytest.approx(2.0)
    position_error = np.linalg.norm(result.x[:, :2] - hold_reference.x[0, :2], axis=1)
    assert position_error.max() < 5e-3
    assert np.abs(result.x[:, 2] - hold_reference.x[0, 2]).max() < 0.05
    assert not result.dropped and result.drop_time_s is None


def test_without_the_controller_the_box_falls(hold_reference, hold_config):
    result = simulate_reference(hold_reference, hold_config, controlled=False)
    assert result.dropped
    assert result.drop_time_s < 0.5
    assert result.x[-1, 1] < hold_reference.x[0, 1] - hold_config.sim.drop_distance  # it fell (gravity -y)


def in_grasp_rotation(scene, angle: float, duration: float, knots: int = 21):
    """A quasi-static reference that turns the grasped box by `angle` about its centre:
    the static hold at every knot (IK, balanced forces), fingertip velocities by
    finite differences."""
    from trajectotree.reference import Reference
    times = np.linspace(0.0, duration, knots)
    holds = [static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=duration,
                                   pose=(0.0, 0.0, angle * t / duration)) for t in times]
    assert all(h is not None for h in holds)
    p_WF = np.stack([h.p_WF[0] for h in holds])
    return Reference(t=times, x=np.stack([h.x[0] for h in holds]), q=np.stack([h.q[0] for h in holds]),
                     p_WF=p_WF, v_WF=np.gradient(p_WF, times, axis=0), f_W=np.stack([h.f_W[0] for h in holds]))


def test_controller_tracks_a_slow_in_grasp_rotation(scene, hold_config):
    reference = in_grasp_rotation(scene, 0.25, 2.0)
    result = simulate_reference(reference, hold_config)
    assert not result.dropped
    assert result.x[-1, 2] == pytest.approx(0.25, abs=0.03)
    assert result.mae_theta < 0.03 and result.mae_x < 3e-3 and result.mae_y < 3e-3
