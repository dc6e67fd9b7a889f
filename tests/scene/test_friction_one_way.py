"""Friction in the plant is set one way (scene.friction.set_friction) for the hands and the object,
box or polygon: every collision geometry carries the scene's (mu, mu), whatever its model file says,
and a plant that registers geometry cannot be given friction without its SceneGraph."""

import pytest
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import ObjectConfig, SceneConfig
from trajectotree.scene.friction import set_friction
from trajectotree.scene.plant import add_polygon_object, build_scene

TRIANGLE = ((0.07, -0.040415), (0.0, 0.080829), (-0.07, -0.040415))  # tests/cli/test_polygon_cli.py


def frictions(scene, instance) -> set:
    """{(static, dynamic)} over the collision geometries of model `instance`'s bodies."""
    plant, inspector = scene.plant, scene.scene_graph.model_inspector()
    out = set()
    for b in plant.GetBodyIndices(instance):
        for g in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
            friction = inspector.GetProximityProperties(g).GetProperty("material", "coulomb_friction")
            out.add((friction.static_friction(), friction.dynamic_friction()))
    return out


@pytest.mark.parametrize("hand", ["planar_hand", "planar_hand5", "drake_planar_gripper"])
@pytest.mark.parametrize("vertices", [None, TRIANGLE])
def test_the_hand_and_the_object_carry_the_scenes_friction(hand, vertices):
    # 0.55: neither the SDFs' 0.7 nor Drake's default
    config = SceneConfig(hand=hand, mu=0.55, object=ObjectConfig(vertices=vertices))
    scene = build_scene(config)
    assert frictions(scene, scene.hand) == {(0.55, 0.55)}
    assert frictions(scene, scene.box) == {(0.55, 0.55)}


def test_a_plant_with_geometry_needs_its_scene_graph():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    instance = add_polygon_object(plant, SceneConfig())
    with pytest.raises(ValueError, match="scene_graph"):
        set_friction(plant, None, instance, 0.5)
