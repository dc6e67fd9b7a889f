"""The object as a Drake model when it is a convex polygon (trajectotree.scene.plant): a prism
generated from the vertices, its mass and inertia against closed forms and against Drake's
own mesh integration, its contact properties, and fingertips holding it in simulation."""

import dataclasses
import math

import numpy as np
import pytest
from pydrake.geometry import Convex
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import CalcSpatialInertia
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import Config, ObjectConfig, SceneConfig
from trajectotree.config.executor import Executor
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import simulate_reference
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.friction import set_friction
from trajectotree.scene.plant import add_polygon_object, box_sdf, build_scene, prism_inertia, prism_points
from trajectotree.search.initial_grasp import initial_grasp_candidates

TRIANGLE = tuple(
    (
        0.14 / math.sqrt(3) * math.cos(math.pi / 2 + 2 * math.pi * k / 3),
        0.14 / math.sqrt(3) * math.sin(math.pi / 2 + 2 * math.pi * k / 3),
    )
    for k in range(3)
)
QUAD = ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04))


def polygon_config(vertices, **scene) -> SceneConfig:
    return SceneConfig(object=ObjectConfig(vertices=vertices), **scene)


def object_body(scene):
    return scene.plant.GetBodyByName("box", scene.box)


def central_inertia(scene) -> np.ndarray:
    return object_body(scene).default_spatial_inertia().CalcRotationalInertia().CopyToFullMatrix3()


def test_a_square_plate_turned_45_degrees_has_the_box_inertia():
    """A square of side s, turned so that it is no box for the code: I_zz = m s^2 / 6 (a plate),
    I_xx = I_yy = m (s^2 + d^2) / 12 (a prism), no product of inertia."""
    s, m, d = 0.12, 0.08, 0.05
    r = s / math.sqrt(2)
    config = polygon_config(((r, 0.0), (0.0, r), (-r, 0.0), (0.0, -r)), box_mass=m, box_depth=d)
    assert not config.shape.is_box
    scene = build_scene(config)
    I = central_inertia(scene)
    assert object_body(scene).default_mass() == m
    np.testing.assert_allclose(
        np.diag(I), [m * (s * s + d * d) / 12, m * (s * s + d * d) / 12, m * s * s / 6], rtol=1e-12
    )
    assert np.abs(I - np.diag(np.diag(I))).max() < 1e-18


def test_the_box_through_the_polygon_builder_equals_box_sdf():
    """The box's corners given to add_polygon_object (a ConvexPolygon without the box's closed
    forms) give the same mass, inertia and friction (set as add_hand_and_box sets both) as box.sdf."""
    config = SceneConfig(box_width=0.16, box_height=0.08, box_mass=0.12, mu=0.4)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    instance = add_polygon_object(plant, config, ConvexPolygon(ConvexPolygon.box(0.16, 0.08).vertices))
    set_friction(plant, scene_graph, instance, config.mu)
    plant.Finalize()
    body = plant.GetBodyByName("box", instance)
    box = build_scene(config)
    np.testing.assert_allclose(
        body.default_spatial_inertia().CalcRotationalInertia().CopyToFullMatrix3(),
        central_inertia(box),
        rtol=1e-12,
        atol=1e-20,
    )
    assert body.default_mass() == object_body(box).default_mass() == 0.12
    (gid,) = plant.GetCollisionGeometriesForBody(body)
    friction = scene_graph.model_inspector().GetProximityProperties(gid).GetProperty("material", "coulomb_friction")
    (box_gid,) = box.plant.GetCollisionGeometriesForBody(object_body(box))
    box_friction = (
        box.scene_graph.model_inspector().GetProximityProperties(box_gid).GetProperty("material", "coulomb_friction")
    )
    assert friction.static_friction() == friction.dynamic_friction() == box_friction.static_friction() == 0.4


@pytest.mark.parametrize("vertices", [TRIANGLE, QUAD])
def test_polygon_inertia_equals_drakes_integration_of_the_prism_mesh(vertices):
    """Drake's CalcSpatialInertia of the Convex prism (uniform density) is an independent closed form."""
    config = polygon_config(vertices, box_mass=0.07)
    shape, d = config.shape, config.box_depth
    expected = CalcSpatialInertia(Convex(prism_points(shape, d), "prism"), 0.07 / (shape.area * d))
    assert expected.get_mass() == pytest.approx(0.07, rel=1e-12)
    np.testing.assert_allclose(expected.get_com(), 0.0, atol=1e-15)  # the vertices are about the centroid
    I = central_inertia(build_scene(config))
    np.testing.assert_allclose(I, expected.CalcRotationalInertia().CopyToFullMatrix3(), rtol=1e-9, atol=1e-15)
    assert I[2, 2] == shape.inertia(0.07)  # the plate inertia the planners and the controller use


def test_polygon_collision_geometry_is_the_extruded_outline_with_the_configured_friction():
    config = polygon_config(TRIANGLE, mu=0.55, box_depth=0.04)
    scene = build_scene(config)
    inspector = scene.scene_graph.model_inspector()
    (gid,) = scene.plant.GetCollisionGeometriesForBody(object_body(scene))
    shape = inspector.GetShape(gid)
    assert isinstance(shape, Convex)
    hull = shape.GetConvexHull()
    corners = np.array([hull.vertex(i) for i in range(hull.num_vertices())])
    assert len(corners) == 6 and set(np.round(corners[:, 2], 12)) == {-0.02, 0.02}
    for v in config.shape.vertices:  # each vertex at both ends of the prism
        assert np.sum(np.all(np.abs(corners[:, :2] - v) < 1e-12, axis=1)) == 2
    friction = inspector.GetProximityProperties(gid).GetProperty("material", "coulomb_friction")
    assert friction.static_friction() == friction.dynamic_friction() == 0.55
    (visual,) = scene.plant.GetVisualGeometriesForBody(object_body(scene))
    assert isinstance(inspector.GetShape(visual), Convex)


def test_a_rectangle_given_as_a_polygon_is_the_box_model():
    """An axis-aligned rectangle's vertices (any order, any orientation) give box.sdf itself."""
    corners = ((-0.1, 0.05), (-0.1, -0.05), (0.1, -0.05), (0.1, 0.05))
    assert box_sdf(polygon_config(corners)) == box_sdf(SceneConfig())
    smaller = ((0.08, 0.04), (-0.08, 0.04), (-0.08, -0.04), (0.08, -0.04))
    assert box_sdf(polygon_config(smaller)) == box_sdf(SceneConfig(box_width=0.16, box_height=0.08))
    scene = build_scene(polygon_config(smaller))
    (gid,) = scene.plant.GetCollisionGeometriesForBody(object_body(scene))
    box = scene.scene_graph.model_inspector().GetShape(gid)
    assert type(box).__name__ == "Box" and (box.width(), box.depth()) == (0.16, 0.08)


def test_prism_inertia_is_symmetric_positive_and_about_the_centroid():
    M = prism_inertia(ConvexPolygon.from_points(QUAD), 0.05, 0.05)
    assert M.get_mass() == 0.05 and np.all(M.get_com() == 0.0)
    assert M.IsPhysicallyValid()


@pytest.mark.slow
def test_fingertips_hold_the_triangle_in_simulation():
    """A static hold of the triangle at the best initial grasp: the grasp controller holds it (the
    fingertips touch the convex prism and carry its weight); with zero torque it drops."""
    config = Config(scene=polygon_config(TRIANGLE))
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))
    scene = build_scene(config.scene)
    grasp = initial_grasp_candidates(scene, config.search).candidates[0]
    reference = static_hold_reference(scene, grasp.arclengths, min_normal_force=1.0, duration=1.0)
    assert reference is not None
    held = simulate_reference(reference, config)
    assert not held.dropped and np.abs(held.x[:, :2]).max() < 2e-3 and np.abs(held.x[:, 2]).max() < 0.02
    late = held.t >= 0.5
    weight = config.scene.box_mass * config.scene.gravity
    assert held.f_W[late, :, 1].sum(axis=1).mean() == pytest.approx(weight, rel=0.02)  # fingers carry m g
    assert np.all(np.linalg.norm(held.f_W[late], axis=2).min(axis=0) > 0.1)  # every finger touches
    dropped = simulate_reference(reference, config, executor=Executor.NONE)
    assert dropped.dropped


def test_scene_graph_distances_from_the_fingertips_are_the_polygons():
    """SceneGraph's signed distance between each fingertip sphere and the prism equals the exact
    planar signed distance of the polygon (trajectotree.geometry) less the tip radius, at a pose
    with the object turned and moved: the Drake geometry is the outline the planners use."""
    config = polygon_config(QUAD, initial_pose=(0.01, -0.02, 0.4))
    scene = build_scene(config)
    context = scene.diagram.CreateDefaultContext()
    q = np.array([0.1, 1.3, -0.3, 1.0, 0.35, 1.1, 0.0, 1.5])
    scene.plant.SetPositions(scene.plant.GetMyMutableContextFromRoot(context), scene.positions(config.initial_pose, q))
    query = scene.scene_graph.get_query_output_port().Eval(scene.scene_graph.GetMyContextFromRoot(context))
    inspector = query.inspector()
    (object_id,) = scene.plant.GetCollisionGeometriesForBody(object_body(scene))
    assert inspector.GetName(object_id) == "box::collision"  # named as box.sdf's
    tips = {
        scene.plant.GetBodyFromFrameId(inspector.GetFrameId(g)).name(): g
        for g in inspector.GetAllGeometryIds()
        if inspector.GetName(g).endswith("tip_collision")
    }
    p_WF = scene.fingertip_positions(q)
    from trajectotree.geometry import world_to_box

    for i in range(4):
        pair = query.ComputeSignedDistancePairClosestPoints(tips[f"finger{i}_link2"], object_id)
        expected = config.shape.signed_distance(world_to_box(config.initial_pose, p_WF[i])) - scene.tip_radius
        assert pair.distance == pytest.approx(expected, abs=1e-6), i
