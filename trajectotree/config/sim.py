"""Full-dynamics execution's configuration (SimConfig)."""

from __future__ import annotations

from dataclasses import dataclass

from trajectotree.config.checks import check_range
from trajectotree.config.controller import check_controller


@dataclass(frozen=True)
class SimConfig:
    """Full-dynamics execution in a discrete MultibodyPlant."""

    time_step: float = 1e-3  # s, discrete plant step
    settle_time: float = 0.5  # s, simulated after the plan ends (the last reference is held)
    drop_distance: float = 0.05  # m, the box is dropped once its position is this far from the plan
    log_period: float = 0.01  # s, sampling period of the logged box pose and hand state (metrics use it)
    controller: str = "grasp"  # executor: "grasp" (GraspController) or "paper" (eq. 20, ImpedanceController)
    push_duration: float = 0.2  # s, how long a push (simulate --push) acts on the box

    def __post_init__(self):
        check_range("sim.time_step", self.time_step, 0.0, 0.01, low_open=True)
        check_range("sim.settle_time", self.settle_time, 0.0, 10.0)
        check_range("sim.drop_distance", self.drop_distance, 0.0, 1.0, low_open=True)
        check_range("sim.log_period", self.log_period, self.time_step, 1.0)
        check_controller(self.controller, "sim.controller")
        check_range("sim.push_duration", self.push_duration, 0.0, 10.0, low_open=True)
