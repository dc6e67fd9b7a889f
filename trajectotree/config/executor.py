"""How a plan is executed, chosen once as one typed value (`Executor`) and dispatched where the
execution Diagram is built (trajectotree.execution.simulate.build_execution_diagram): the paper's
eq. 20 fingertip impedance controller (open loop only), the object-level grasp controller open loop,
closed loop (monitors, estimators and reflexes around it) or closed loop with replanning. A
combination the executors do not have (eq. 20 with the closed loop) has no value to name it."""

from __future__ import annotations

from enum import Enum

from trajectotree.config.checks import ConfigError
from trajectotree.config.controller import check_controller


class Executor(Enum):
    """An executor; its value is its name in the CLI (`--executor`), the execution folders and the tables."""

    GRASP = "grasp"  # the object-level grasp controller on the plan's friction and mass
    GRASP_CLOSED_LOOP = "grasp-closed-loop"  # the grasp controller fed by the closed loop's estimates and reflexes
    GRASP_REPLAN = "grasp-replan"  # the closed loop, planning again when the plan no longer holds
    PAPER = "paper"  # eq. 20, the fingertip impedance controller of the paper
    NONE = "none"  # zero torque: the hand's motors off (checks that a controller is what holds the object)

    @property
    def controller(self) -> str:
        """The controller it runs (config.CONTROLLERS), or "none"."""
        return {Executor.PAPER: "paper", Executor.NONE: "none"}.get(self, "grasp")

    @property
    def closed_loop(self) -> bool:
        """It adds the closed loop (trajectotree.execution.closed_loop) around its controller."""
        return self in (Executor.GRASP_CLOSED_LOOP, Executor.GRASP_REPLAN)

    @property
    def replans(self) -> bool:
        return self is Executor.GRASP_REPLAN


EXECUTORS = tuple(e.value for e in Executor)


def parse_executor(name, field: str = "executor") -> Executor:
    """The Executor named `name` (an Executor passes through); ConfigError naming `field`, the value and the names."""
    if isinstance(name, Executor):
        return name
    try:
        return Executor(name)
    except ValueError:
        raise ConfigError(field=field, value=name, problem="is not an executor", choices=EXECUTORS) from None


def executor_of(controller: str, *, closed_loop: bool = False, replan: bool = False) -> Executor:
    """The executor the older options name: a controller (config.CONTROLLERS), with the closed loop or
    replanning (the grasp controller's only); ConfigError for the eq. 20 controller with either."""
    check_controller(controller)
    if not (closed_loop or replan):
        return Executor(controller)
    if controller != "grasp":
        raise ConfigError(
            field="controller",
            value=controller,
            problem=": the closed loop runs around the grasp controller only",
            choices=("grasp",),
        )
    return Executor.GRASP_REPLAN if replan else Executor.GRASP_CLOSED_LOOP
