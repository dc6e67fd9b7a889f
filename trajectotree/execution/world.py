"""The simulated world where it differs from the plan's (`Conditions`): the friction coefficient
(sim_mu), the box mass (sim_mass: model mismatch) and a push, a force on the box in W for
SimConfig.push_duration seconds (`Push`, applied by the `PushSource` system: (f_x, f_y) in the plane,
(f_x, f_y, f_z) in space). The controller never sees them: it keeps the plan's values.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from trajectotree.config import MAX_BOX_MASS, MAX_MU, MIN_BOX_MASS, ConfigError, check_length, check_range


@dataclass(frozen=True)
class Push:
    """A force on the box's centre, in W, from time_s for duration_s."""

    force: tuple[float, ...]  # N, (f_x, f_y) in W for a planar plan, (f_x, f_y, f_z) for a plan in space
    time_s: float  # s, when it starts
    duration_s: float = 0.2  # s, how long it acts

    def __post_init__(self):
        check_length("push force", self.force, 3 if len(self.force) == 3 else 2, "f_x N, f_y N[, f_z N in space]")
        for i, f in enumerate(self.force):
            check_range("push force", f, -100.0, 100.0, index=(i,))
        check_range("push time", self.time_s, 0.0, None)
        check_range("push duration", self.duration_s, 0.0, 10.0, low_open=True)


# The push's spelling per force components (2: a planar plan, 3: a plan in space): the form and what it says.
PUSH_FORMS = {
    2: "FX,FY@T (force in N in W, start time in s, e.g. 0.2,0@3.5)",
    3: "FX,FY,FZ@T (a plan in space is pushed in 3D: force in N in W, start time in s, e.g. 1,0,0@2.5)",
}


def parse_push(text: str, duration_s: float = 0.2, components: int = 2) -> Push:
    """A Push from "FX,FY@T" (N, N, s), e.g. "0.2,0@3.5", or with components=3 (a plan in space) "FX,FY,FZ@T";
    ConfigError naming the text and the form."""
    try:
        force, at = str(text).split("@")
        values = tuple(float(v) for v in force.split(","))
        start = float(at)
        if len(values) != components:
            raise ValueError(f"{len(values)} force components")
    except ValueError:
        raise ConfigError(f"push {text!r} is not {PUSH_FORMS[components]}") from None
    try:
        return Push(force=values, time_s=start, duration_s=duration_s)
    except ConfigError as e:
        raise ConfigError(f"push {text!r}: {e}") from None


@dataclass(frozen=True)
class Conditions:
    """The simulated world where it differs from the plan's; the controller keeps the plan's values."""

    mu: float | None = None  # friction coefficient of the simulated plant (None: the scene's)
    mass: float | None = None  # kg, box mass of the simulated plant (None: the scene's)
    push: Push | None = None  # a push on the box, or none

    def __post_init__(self):
        if self.mu is not None:
            check_range("sim_mu", self.mu, 0.0, MAX_MU, low_open=True)
        if self.mass is not None:
            check_range("sim_mass", self.mass, MIN_BOX_MASS, MAX_BOX_MASS)

    def simulated_object(self, box):
        """The simulated plant's object in space (a scene.spatial.SpaceObject: its mu and mass replaced)."""
        changes = {k: v for k, v in (("mu", self.mu), ("mass", self.mass)) if v is not None}
        return dataclasses.replace(box, **changes)

    def scene(self, scene_config):
        """The simulated plant's SceneConfig."""
        changes = {k: v for k, v in (("mu", self.mu), ("box_mass", self.mass)) if v is not None}
        if self.mass is not None and scene_config.object_inertia is not None:  # the same body, heavier
            changes["object_inertia"] = scene_config.inertia_zz(self.mass)
        return dataclasses.replace(scene_config, **changes)

    def push_speed(self, scene_config) -> float:
        """m/s, the most speed the push can give the simulated object: its impulse over the object's mass."""
        if self.push is None:
            return 0.0
        return math.hypot(*self.push.force) * self.push.duration_s / self.scene(scene_config).box_mass

    def to_json(self, scene_config) -> dict:
        return self.world_json(scene_config.mu, scene_config.box_mass)

    def world_json(self, plan_mu: float, plan_mass: float) -> dict:
        """sim.json's `conditions`: the simulated and the planned friction and mass (kg), and the push."""
        push = (
            None
            if self.push is None
            else {"force": list(self.push.force), "time_s": self.push.time_s, "duration_s": self.push.duration_s}
        )
        return {
            "sim_mu": plan_mu if self.mu is None else self.mu,
            "sim_mass": plan_mass if self.mass is None else self.mass,
            "plan_mu": plan_mu,
            "plan_mass": plan_mass,
            "push": push,
        }


NOMINAL = Conditions()  # the plan's world (frozen: a default argument every caller may share)


class PushSource(LeafSystem):
    """Output port `spatial_forces` (list of ExternallyAppliedSpatialForce, for the
    plant's applied-spatial-force input): the push on the box while it acts, else none."""

    def __init__(self, plant, box, push: Push):
        super().__init__()
        self._body = plant.GetBodyByName("box", box).index()
        self._push = push
        self.spatial_forces_port = self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self.CalcForces
        )

    def CalcForces(self, context, output):
        push, t = self._push, context.get_time()
        forces = []
        if push.time_s <= t < push.time_s + push.duration_s:
            applied = ExternallyAppliedSpatialForce()
            applied.body_index = self._body
            applied.p_BoBq_B = np.zeros(3)  # at the box origin, its centre of mass
            f_W = np.zeros(3)  # a planar push has no f_z
            f_W[: len(push.force)] = push.force
            applied.F_Bq_W = SpatialForce(np.zeros(3), f_W)
            forces.append(applied)
        output.set_value(forces)
