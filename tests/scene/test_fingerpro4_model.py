"""models/fingerpro4.sdf: the four TriFinger Pro fingers as Drake reads them, the file in step with its
generator (scripts/fingerpro4_model.py), and the chosen mount reaching every face of the cube."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

SCRIPTS = Path(__file__).parents[2] / "scripts"
MODEL = Path(__file__).parents[2] / "models" / "fingerpro4.sdf"


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, SCRIPTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def plant():
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(MODEL))
    plant.Finalize()
    return plant


def test_the_model_is_its_generators_output():
    assert MODEL.read_text() == _script("fingerpro4_model").hand_sdf()


def test_four_fingers_of_three_joints_with_the_published_limits_masses_and_motors(plant):
    assert plant.num_positions() == 12 and plant.num_actuators() == 12
    for a in plant.GetJointActuatorIndices():
        assert plant.get_joint_actuator(a).effort_limit() == pytest.approx(0.396)
    limits = np.array([[-0.33, 1.0], [0.0, 1.57], [-2.7, 0.0]] * 4)
    np.testing.assert_allclose(np.c_[plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()], limits)
    masses = [plant.GetBodyByName(f"finger0_link{k}").default_mass() for k in (1, 2, 3)]
    np.testing.assert_allclose(masses, [0.267, 0.272, 0.0557 + 0.0092])


def test_fingers_are_quarter_turns_of_each_other_about_the_vertical(plant):
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.tile([0.3, 0.8, -1.5], 4))
    p = np.array([plant.GetFrameByName(f"finger{i}_tip").CalcPoseInWorld(context).translation() for i in range(4)])
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for i in range(3):
        np.testing.assert_allclose(p[i + 1], quarter @ p[i], atol=1e-9)


def test_the_chosen_mount_reaches_every_face_of_the_cube_with_two_fingers_or_more():
    reach = _script("fingerpro4_reach")
    fractions = reach.per_finger(reach.measure(reach.model.MOUNT))
    assert np.all(np.sum(fractions > 0, axis=0) >= 2), fractions
