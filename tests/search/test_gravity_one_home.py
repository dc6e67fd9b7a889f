"""The fingers' gravity torques in the plane have one home, the closed form (scene.hand_model's
FingerGeometry.gravity_gains, vectorized by scene.dynamics.HandModel) that the payload, the stance
and the CITO programs use: it is the plant's CalcGravityGeneralizedForces on every planar hand."""

import numpy as np
import pytest

from trajectotree.config import SceneConfig
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import build_scene


@pytest.mark.parametrize("hand", ["planar_hand", "planar_hand5", "drake_planar_gripper"])
def test_the_closed_form_is_the_plants_gravity_on_every_planar_hand(hand):
    scene = build_scene(SceneConfig(hand=hand))
    plant, context = scene.plant, scene.plant.CreateDefaultContext()
    model = HandModel.from_scene(scene)
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = np.concatenate([rng.uniform(f.q_lower, f.q_upper) for f in scene.fingers])
        plant.SetPositions(context, scene.positions(scene.config.initial_pose, q))
        tau_plant = plant.CalcGravityGeneralizedForces(context)[scene.hand_v_indices]
        tau_closed = model.gravity_forces(q)  # (F, 2): gravity's generalized force
        assert np.max(np.abs(tau_plant)) > 1e-3  # the links weigh something at these angles
        np.testing.assert_allclose(tau_closed.ravel(), tau_plant, rtol=0, atol=1e-12)
        # the torque that holds each finger up is its negative (FingerGeometry's form, the stance's)
        holding = [f.gravity_torques(qi, scene.config.gravity) for f, qi in zip(scene.fingers, q.reshape(-1, 2))]
        np.testing.assert_allclose(np.ravel(holding), -tau_closed.ravel(), rtol=0, atol=1e-15)
