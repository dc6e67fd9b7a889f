"""Execution of hands other than the four-finger one: the five-finger hand and Drake's planar
gripper (three fingers) hold the object still in a short simulation, open and closed loop."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, SceneConfig
from trajectotree.config.executor import Executor
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import build_execution_diagram, simulate_reference
from trajectotree.scene.plant import build_scene

# (scene, contact arclengths: `trajectotree scene --json`'s best initial grasp of each)
HANDS = {
    "planar_hand5": (SceneConfig(hand="planar_hand5"), (0.06, 0.2, 0.34, 0.5, 0.58)),
    "drake_planar_gripper": (
        SceneConfig(hand="drake_planar_gripper", box_width=0.1, box_height=0.1, box_mass=0.028),
        (0.24, 0.06, 0.32),
    ),
}


def short_config(scene_config: SceneConfig) -> Config:
    config = Config()
    return dataclasses.replace(config, scene=scene_config, sim=dataclasses.replace(config.sim, settle_time=0.2))


@pytest.mark.parametrize("hand", sorted(HANDS))
@pytest.mark.parametrize("executor", [Executor.GRASP, Executor.GRASP_CLOSED_LOOP])
def test_a_hand_of_three_or_five_fingers_holds_the_object_in_simulation(hand, executor):
    scene_config, arclengths = HANDS[hand]
    scene = build_scene(scene_config)
    F = scene.num_fingers
    config = short_config(scene_config)
    reference = static_hold_reference(scene, arclengths, min_normal_force=1.0, duration=0.3)
    assert reference is not None
    execution = build_execution_diagram(reference, config, executor=executor)
    assert execution.hand_description.num_fingers == F == len(arclengths)
    result = simulate_reference(reference, config, executor=executor)
    T = len(result.t)
    assert result.q.shape == (T, 2 * F) and result.f_W.shape == (T, F, 2)
    assert not result.dropped
    assert np.max(result.abs_error[:, :2]) < 2e-3 and np.max(result.abs_error[:, 2]) < 0.02
    # Every finger pushes at the end, and together they carry the object's weight.
    end = result.f_W[-1]
    assert np.all(np.linalg.norm(end, axis=1) > 0.1)
    np.testing.assert_allclose(end.sum(axis=0), [0.0, scene_config.box_mass * scene_config.gravity], atol=0.05)
