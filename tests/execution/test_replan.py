"""Replanning during execution (trajectotree.execution.replan): at a plan's nodes the closed loop's
estimates decide whether to plan again from the measured state; the run is one continuous log."""

import dataclasses

import numpy as np
import pytest

from trajectotree.config import Config, ReplanConfig
from trajectotree.execution.replan import simulate_replanning
from trajectotree.execution.simulate import Conditions
from trajectotree.planning.planners import plan
from trajectotree.results import ReplanReason


@pytest.mark.slow
def test_a_world_with_less_friction_replans_from_the_measured_state_with_the_estimate():
    config = Config()
    config = dataclasses.replace(config, sim=dataclasses.replace(config.sim, replan=ReplanConfig(max_replans=1)))
    result = plan(goal=2.2, config=config)
    assert result.success, result.status
    run = simulate_replanning(result, config, conditions=Conditions(mu=0.4))
    assert len(run.replans) == 1
    event = run.replans[0]
    assert event.reason is ReplanReason.FRICTION  # the estimate fell below the plan's 0.7
    assert 0.3 <= event.mu <= 0.45 and event.mass == pytest.approx(0.05, rel=0.05)
    assert event.takes_effect_s == pytest.approx(event.time_s + event.latency_s)
    # the node the state was measured at is a node of the plan (1.2 s segments)
    assert event.time_s / 1.2 == pytest.approx(round(event.time_s / 1.2))
    assert np.all(np.diff(run.t) > 0) and run.t[-1] >= result.trajectory.t[-1]  # one log over the whole run
    assert run.to_json()["replans"][0]["reason"] == "friction"
