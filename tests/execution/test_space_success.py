"""sim.json of a run in space (execution.space_run.SpaceSimResult.to_json) gives the final orientation error in deg
beside rad and the field's two success criteria: no drop and a final orientation error within 15 deg
(within_15deg) or within 0.4 rad = 22.9 deg (within_0p4rad); `dropped` stays the plane's rule (the cube's centre
sim.drop_distance off the plan's), so a run can end within both angles and still count as dropped."""

import json

import numpy as np
import pytest

from trajectotree.execution.space_run import SpaceSimResult


def _result(final_deg: float, dropped: bool) -> SpaceSimResult:
    """A 3-sample run of a four-finger hand whose orientation error grows to final_deg (the arrays' contents do not
    enter the summary's criteria)."""
    t = np.array([0.0, 0.5, 1.0])
    x = np.tile([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], (3, 1))
    return SpaceSimResult(
        t=t,
        x=x,
        x_plan=x,
        q=np.zeros((3, 12)),
        f_W=np.zeros((3, 4, 3)),
        f_W_plan=np.zeros((3, 4, 3)),
        executor="grasp",
        dropped=dropped,
        drop_time_s=0.5 if dropped else None,
        orientation_error_rad=np.radians([0.0, 0.5 * final_deg, final_deg]),
        position_error_m=np.array([0.0, 0.06 if dropped else 0.001, 0.001]),
        sim_time_s=1.0,
        world={},  # the plan's world
    )


@pytest.mark.parametrize(
    "final_deg, dropped, within_15deg, within_0p4rad",
    [
        (14.9, False, True, True),
        (15.1, False, False, True),
        (22.8, False, False, True),  # 0.398 rad
        (23.0, False, False, False),  # 0.401 rad
        (1.0, True, False, False),  # dropped on the way, back near the plan at the end
    ],
)
def test_the_two_criteria(final_deg, dropped, within_15deg, within_0p4rad):
    summary = json.loads(json.dumps(_result(final_deg, dropped).to_json()))  # as sim.json holds it
    assert summary["final_orientation_error_deg"] == pytest.approx(final_deg)
    assert summary["final_orientation_error_rad"] == pytest.approx(np.radians(final_deg))
    assert summary["dropped"] is dropped
    assert summary["within_15deg"] is within_15deg and summary["within_0p4rad"] is within_0p4rad
