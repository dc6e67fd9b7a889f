"""One home for the execution's math: the fingers' gravity torques (scene.dynamics.HandModel, which the
controllers' HandKinematics reads, equal to the plant's), the angle wrap (geometry.wrap_angle) and the
first-order low-pass step (closed_loop.low_pass_step, of the mass estimate and the cones' friction)."""

from pathlib import Path

import numpy as np
import pytest

import trajectotree
from trajectotree.config import ControllerGains, with_values
from trajectotree.execution.closed_loop import low_pass_step
from trajectotree.execution.fingers import HandKinematics
from trajectotree.execution.reflexes import ConeFriction
from trajectotree.geometry import wrap_angle
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import build_scene

EXECUTION = Path(trajectotree.__file__).parent / "execution"


def test_the_controllers_gravity_torques_are_the_hand_models_and_the_plants():
    scene = build_scene()
    rng = np.random.default_rng(0)
    kinematics = HandKinematics(scene.fingers, scene.config.gravity)
    model = HandModel.from_fingers(scene.fingers, scene.config.gravity)
    context = scene.plant.CreateDefaultContext()
    for q in rng.uniform(-1.5, 1.5, size=(5, 2 * scene.num_fingers)):
        g = kinematics(q)[2]
        np.testing.assert_array_equal(g, -model.gravity_forces(q))
        scene.plant.SetPositions(context, scene.positions(scene.config.initial_pose, q))
        plant_g = -scene.plant.CalcGravityGeneralizedForces(context)[scene.hand_v_indices]
        np.testing.assert_allclose(g.ravel(), plant_g, rtol=1e-10, atol=1e-12)


def test_angles_wrap_into_minus_pi_to_pi_in_one_place():
    np.testing.assert_allclose(
        wrap_angle(np.array([0.0, np.pi / 2, 3 * np.pi / 2, -3 * np.pi / 2])), [0, 1.5708, -1.5708, 1.5708], atol=1e-4
    )
    assert wrap_angle(np.pi) == pytest.approx(-np.pi)
    sources = "".join(path.read_text() for path in EXECUTION.glob("*.py"))
    assert "% (2 * np.pi)" not in sources  # the controller and the monitor call geometry.wrap_angle


def test_the_cones_friction_is_the_low_pass_step_of_the_estimate():
    gains = with_values(ControllerGains(), {"grasp.cone_time_constant": 0.05})
    cones = ConeFriction(gains, mu_assumed=0.7)
    gain = 1.0 / (gains.rate_hz * 0.05)
    assert cones.cone_friction(0.7, 0.3) == low_pass_step(0.7, 0.3, gain) == pytest.approx(0.7 - 0.4 * gain)
    assert low_pass_step(np.array([1.0, 2.0]), np.array([3.0, 2.0]), 1.0).tolist() == [3.0, 2.0]
