"""The plan in effect: what every system that follows the plan reads through its abstract input port
`plan` (the grasp controller, the landing reflex, the contact monitor and the friction estimator), from
one source: a constant for a plan executed as planned, the replanner's output `plan` for one that is
replanned (trajectotree.execution.replan.Replanner), so that a plan swapped in reaches them all at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import InputPort, LeafSystem
from pydrake.systems.primitives import ConstantValueSource

from trajectotree.config import Config
from trajectotree.execution.reference import GraspSchedule, Reference, grasp_schedule
from trajectotree.scene.plant import Scene

PLAN_PORT = "plan"


@dataclass(frozen=True, eq=False)
class PlanInEffect:
    """The plan the executor follows now: its `reference` (a replanned run's: the old plan up to each
    swap, the hold while the planner ran, then the new plan), the grasp controller's `schedule` of it,
    the friction `mu_assumed` it assumes (a new plan's: the estimate it was planned with) and its
    `version` (0 the first plan, one more at each swap: a system that keeps state along the plan, as the
    landing reflex its clocks, starts again on a new version)."""

    reference: Reference
    schedule: GraspSchedule
    mu_assumed: float
    version: int = 0

    def __deepcopy__(self, memo) -> PlanInEffect:
        # Immutable: a context's copy (Drake copies abstract state at each unrestricted update) shares it.
        return self


def execution_schedule(reference: Reference, config: Config, scene: Scene) -> GraspSchedule:
    """The grasp controller's schedule of `reference`, sampled at its rate, to the run's end
    (the plan, then config.sim.settle_time of hold)."""
    gains = config.controller
    return grasp_schedule(
        reference,
        shape=config.scene.shape,
        tip_radius=scene.tip_radius,
        period=1.0 / gains.rate_hz,
        duration=reference.duration + config.sim.settle_time,
        ramp_time=gains.grasp.ramp_time,
        swing_lift=gains.grasp.swing_lift,
        contact_distance=gains.grasp.contact_distance,
    )


def plan_in_effect(reference: Reference, config: Config, scene: Scene, mu_assumed: float, version: int = 0):
    """The PlanInEffect of `reference` (its schedule: execution_schedule)."""
    return PlanInEffect(reference, execution_schedule(reference, config, scene), mu_assumed, version)


def declare_plan_input(system: LeafSystem) -> InputPort:
    """Declares `system`'s abstract input port `plan` (a PlanInEffect)."""
    return system.DeclareAbstractInputPort(PLAN_PORT, AbstractValue.Make(object()))


def add_plan_source(builder, plan: PlanInEffect) -> ConstantValueSource:
    """A source of `plan` for the whole run (its output port feeds the systems' `plan` inputs)."""
    return builder.AddNamedSystem("plan_in_effect", ConstantValueSource(AbstractValue.Make(plan)))
