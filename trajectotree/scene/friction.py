"""Contact friction in a plant, set one way: after a model is parsed or registered, every collision
geometry of its bodies gets the Coulomb friction (mu, mu) in SceneGraph's proximity properties
(Drake combines the two coefficients of a contact pair; equal values on both sides keep mu).
"""

from __future__ import annotations

from pydrake.geometry import ProximityProperties, RoleAssign, SceneGraph
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant


def set_friction(plant: MultibodyPlant, scene_graph: SceneGraph | None, instance, mu: float) -> None:
    """Gives the collision geometries of model `instance`'s bodies static and dynamic friction `mu`
    in `scene_graph` (the plant's); a plant that registers no geometry has none to set."""
    if not plant.geometry_source_is_registered():
        return
    if scene_graph is None:
        raise ValueError("pass the plant's scene_graph to set its models' friction")
    inspector = scene_graph.model_inspector()
    for b in plant.GetBodyIndices(instance):
        for g in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
            properties = ProximityProperties(inspector.GetProximityProperties(g))
            properties.UpdateProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
            scene_graph.AssignRole(plant.get_source_id(), g, properties, RoleAssign.kReplace)
