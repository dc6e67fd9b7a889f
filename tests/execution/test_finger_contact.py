"""The simulation's fingers collide with each other like any other bodies: SceneGraph filters no
pair of geometries of two different fingers, only each finger's adjacent links (as MultibodyPlant
does for bodies joined by a joint)."""

from __future__ import annotations

import itertools

from trajectotree.config import Config
from trajectotree.execution.reference import reference_from_plan
from trajectotree.execution.simulate import build_execution_diagram
from trajectotree.io import load_plan
from trajectotree.scene.hand import finger_bodies
from trajectotree.scene.plant import build_scene


def test_the_execution_diagram_lets_two_fingers_collide(tiny_plan):
    plan = load_plan(tiny_plan)
    built = build_execution_diagram(reference_from_plan(plan, build_scene(plan.config.scene)), Config())
    plant = built.plant
    graph = built.diagram.GetSubsystemByName("scene_graph")
    context = built.diagram.CreateDefaultContext()
    inspector = graph.get_query_output_port().Eval(graph.GetMyContextFromRoot(context)).inspector()
    geometries = [
        [g for body in finger_bodies(plant, built.hand, f) for g in plant.GetCollisionGeometriesForBody(body)]
        for f in built.hand_description.fingers
    ]
    for i, j in itertools.combinations(range(len(geometries)), 2):
        for a, b in itertools.product(geometries[i], geometries[j]):
            assert not inspector.CollisionFiltered(a, b), (i, j)
    # each finger's own links touch at their joint: filtered, as Drake does for adjacent bodies
    link1, link2 = (
        plant.GetCollisionGeometriesForBody(b)
        for b in finger_bodies(plant, built.hand, built.hand_description.fingers[0])[:2]
    )
    assert inspector.CollisionFiltered(link1[0], link2[0])
