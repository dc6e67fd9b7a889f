"""The hand in space (fingerpro4) and its free box in a Drake plant: the plant's shape, the
closed-form kinematics (kinematics.SerialFinger) against the plant, and the scene command."""

import json
from pathlib import Path

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces

from trajectotree.cli import main
from trajectotree.config import ConfigError
from trajectotree.scene.hand_file import space_hand_file
from trajectotree.scene.spatial import START_POSE, build_space_scene


@pytest.fixture(scope="module")
def scene():
    return build_space_scene("fingerpro4", mu=0.7, gravity=9.81)


def test_the_plant_holds_four_three_joint_fingers_and_a_free_cube(scene):
    plant = scene.plant
    assert plant.num_positions() == 12 + 7 and plant.num_velocities() == 12 + 6 and plant.num_actuators() == 12
    assert plant.GetJointByName("box_floating").type_name() == "quaternion_floating"
    np.testing.assert_array_equal(plant.gravity_field().gravity_vector(), [0.0, 0.0, -9.81])
    body = plant.GetBodyByName("box", scene.box)
    assert body.default_mass() == pytest.approx(0.094) and scene.object.size == (0.065, 0.065, 0.065)
    inertia = body.default_rotational_inertia().CopyToFullMatrix3()
    np.testing.assert_allclose(np.diag(inertia), [0.094 * 2 * 0.065**2 / 12] * 3)
    assert scene.tip_radius == 0.01 and np.all(scene.tau_max == 0.396)


def _random_q(scene, rng):
    f = scene.fingers[0]
    return rng.uniform(f.q_lower, f.q_upper, size=(scene.num_fingers, 3))


def test_closed_form_fingertips_and_jacobians_match_the_plant(scene):
    plant, rng = scene.plant, np.random.default_rng(1)
    context = plant.CreateDefaultContext()
    for _ in range(5):
        q = _random_q(scene, rng)
        plant.SetPositions(context, scene.positions(START_POSE, q))
        for i, finger in enumerate(scene.fingers):
            frame = scene.tip_frame(i)
            np.testing.assert_allclose(finger.fingertip(q[i]), frame.CalcPoseInWorld(context).translation(), atol=1e-12)
            # a point fixed on the last link off the centre: a contact point r from it
            p_FQ_W = np.array([0.004, -0.006, 0.007])
            p_FQ_F = frame.CalcPoseInWorld(context).rotation().inverse() @ p_FQ_W
            J = plant.CalcJacobianTranslationalVelocity(
                context, JacobianWrtVariable.kQDot, frame, p_FQ_F, plant.world_frame(), plant.world_frame()
            )
            columns = scene.hand_q_indices[3 * i : 3 * i + 3]
            np.testing.assert_allclose(finger.jacobian(q[i], p_FQ_W), J[:, columns], atol=1e-12)


def test_fingertips_vectorize_over_joint_angles(scene):
    q = _random_q(scene, np.random.default_rng(2))
    finger = scene.fingers[0]
    np.testing.assert_allclose(finger.fingertip(q), [finger.fingertip(row) for row in q], atol=1e-15)


def test_gravity_torques_hold_the_fingers_still(scene):
    plant = scene.plant
    context = plant.CreateDefaultContext()
    q = _random_q(scene, np.random.default_rng(3))
    plant.SetPositions(context, scene.positions(START_POSE, q))
    u = np.zeros(plant.num_velocities())
    v = [plant.GetJointByName(n, scene.hand).velocity_start() for f in scene.hand_file.fingers for n in f.joints]
    u[v] = scene.gravity_torques(q).ravel()
    forces = MultibodyForces(plant)
    plant.CalcForceElementsContribution(context, forces)  # gravity
    forces.mutable_generalized_forces()[:] += u
    residual = plant.CalcInverseDynamics(context, np.zeros(plant.num_velocities()), forces)  # what else zero vdot needs
    np.testing.assert_allclose(residual[v], 0.0, atol=1e-12)
    assert np.max(np.abs(scene.gravity_torques(q))) > 0.05  # N m: the fingers' weight is no rounding


def test_the_scene_command_reports_each_fingers_faces_and_workspace(capsys):
    assert main(["scene", "--hand", "fingerpro4", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["kind"] == "space" and report["num_actuators"] == 12 and len(report["fingers"]) == 4
    reach = report["reach"]
    assert reach["faces"] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert min(reach["fingers_per_face"]) >= 2  # every face by two fingers at least (docs/measurements.md)
    assert reach["reachable_contacts"][0][0] == 9  # finger 0 reaches all of the face it stands behind
    low, high = np.array(report["fingers"][0]["tip_workspace_W"])
    assert np.all(low < high)


def test_a_planar_goal_for_a_hand_in_space_is_refused(tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", "--hand", "fingerpro4", "--goal", "0.3", "--out", str(out)]) == 2  # a planar goal
    assert "--goal = 0.3 is a planar goal; valid: --goal-quat W X Y Z or --goal-rpy R P Y" in capsys.readouterr().err
    assert not out.exists()


def test_a_hand_in_space_without_its_model_is_refused(tmp_path):
    path = tmp_path / "hand.yaml"
    path.write_text("kind: space\nmodel: missing.sdf\nfingers: []\n")
    with pytest.raises(ConfigError, match="missing.sdf' does not exist"):
        space_hand_file(str(path))
    assert main(["scene", "--hand", str(path)]) == 2


def test_the_built_in_description_names_the_model_beside_it():
    hand = space_hand_file("fingerpro4")
    assert Path(hand.model).name == "fingerpro4.sdf" and len(hand.fingers) == 4
    assert hand.object.size == (0.065, 0.065, 0.065) and hand.object.mass == 0.094
