"""Replanning a plan in space (execution.space_replan: the space side of the one Replanner): the measured 3D start
from the cube's floating-joint state, its validation before any planning (typed refusals), the reference edits of a
replan (the hold while the planner runs, the new plan's segments as scheduled) and, slow, `simulate --replan` of a
3D plan in a world of friction 0.4 end to end."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError
from trajectotree.execution.replan import replan
from trajectotree.execution.space_control import SpaceReference
from trajectotree.execution.space_replan import SpacePlanning, space_delayed, space_off_plan, space_scheduled
from trajectotree.results import ReplanOutcome, ReplanReason
from trajectotree.scene.spatial import build_space_scene
from trajectotree.start import StartProblem


@pytest.fixture(scope="module")
def planning() -> SpacePlanning:
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    F, J = scene.num_fingers, sum(len(f.q_lower) for f in scene.fingers)
    pose = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.1]
    held = SpaceReference.held(pose, np.zeros(J), np.zeros((F, 3)), np.zeros((F, 3)), np.zeros((F, 3)), 2.0)
    return SpacePlanning((1.0, 0.0, 0.0, 0.0), held, config, scene, segment_workers=1)


def mid_joints(planning: SpacePlanning) -> np.ndarray:
    """Each joint halfway between its limits (a state of the hand, its fingertips nowhere near the cube)."""
    return np.concatenate([0.5 * (f.q_lower + f.q_upper) for f in planning.scene.fingers])


def test_the_measured_3d_start_is_the_cubes_floating_joint_state_and_the_hands_joints(planning):
    q = mid_joints(planning)
    box = np.array([2.0, 0.0, 0.0, 0.0, 0.01, -0.02, 0.1, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03])  # quaternion of norm 2
    start = planning.measured_start(box, np.concatenate([q, np.ones_like(q)]))
    assert start.object_pose == (1.0, 0.0, 0.0, 0.0, 0.01, -0.02, 0.1)  # normalized, position kept
    assert start.object_velocity == (0.1, 0.2, 0.3, 0.01, 0.02, 0.03)  # [w_W, v_W]
    np.testing.assert_array_equal(start.q, q)
    with pytest.raises(ConfigError, match=r"start.object_pose\[0:4\] = \[0.0, 0.0, 0.0, 0.0\] has norm 0"):
        planning.measured_start(np.zeros(13), np.zeros(2 * len(q)))


@pytest.mark.parametrize(
    "velocity, q_change, problem",
    [
        ((0.0, 0.0, 0.0, 0.5, 0.0, 0.0), None, StartProblem.MOVING),  # 0.5 m/s
        ((2.0, 0.0, 0.0, 0.0, 0.0, 0.0), None, StartProblem.SPINNING),  # 2 rad/s
        ((0.0,) * 6, "drop", StartProblem.WRONG_SIZE),
        ((0.0,) * 6, "limit", StartProblem.JOINT_LIMIT),
        ((0.0,) * 6, None, StartProblem.FINGER_OFF),  # at rest, the fingertips off the cube
    ],
)
def test_a_3d_start_the_planner_cannot_take_is_a_typed_refusal_before_any_search(planning, velocity, q_change, problem):
    """replan() of a measured 3D start that is no grasp at rest: START_REFUSED with the start's refusal, no search."""
    q = mid_joints(planning)
    if q_change == "limit":
        q[2] = planning.scene.fingers[0].q_upper[2] + 1e-3
    box = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.1, *velocity])
    start = planning.measured_start(box, np.concatenate([q, np.zeros_like(q)]))
    if q_change == "drop":  # a state of another hand
        start = dataclasses.replace(start, q=start.q[:-1])
    event, solved = replan(planning, start, 1.0, ReplanReason.FRICTION, 0.4, 0.094)
    assert solved is None and not event.planned
    assert event.outcome is ReplanOutcome.START_REFUSED and event.refusal.problem is problem
    assert math.isnan(event.search_s) and event.takes_effect_s == 1.0 + event.latency_s
    assert event.to_json()["outcome"] == "start_refused" and event.to_json()["refusal"]["kind"] == "start"


def _moving_reference() -> SpaceReference:
    """Three knots 1 s apart: the cube at rest at 0, moving up at 1 s (0.1 m/s), at rest at 2 s 0.1 m higher."""
    t = np.array([0.0, 1.0, 2.0])
    x = np.array([[1.0, 0, 0, 0, 0, 0, z] for z in (0.0, 0.05, 0.1)])
    v = np.array([[0, 0, 0, 0, 0, s] for s in (0.0, 0.1, 0.0)], dtype=float)
    q = np.array([[0.1], [0.2], [0.3]])
    f = np.arange(9.0).reshape(3, 1, 3)
    return SpaceReference(t=t, x=x, v=v, q=q, f_W=f, p_W_C=f + 1.0, p_W_tip=f + 2.0)


def test_a_held_space_reference_holds_its_state_for_the_delay_then_goes_on():
    reference = _moving_reference()
    delayed = space_delayed(reference, 1.0, 0.5)
    np.testing.assert_allclose(delayed.t, [0.0, 1.0, 1.5, 2.5])
    hold = delayed.pose_at([1.0, 1.2, 1.5])
    np.testing.assert_allclose(hold, np.tile(reference.pose_at([1.0])[0], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(delayed.v[1:3], 0.0)  # at rest while held
    np.testing.assert_allclose(delayed.q[1:3, 0], 0.2)
    np.testing.assert_allclose(delayed.pose_at([2.5]), reference.pose_at([2.0]), atol=1e-12)
    assert space_delayed(reference, 1.0, 0.0) is reference


def test_a_new_space_plan_holds_at_a_node_until_its_segment_is_ready():
    reference = _moving_reference()
    held, arrivals = space_scheduled(reference, 1, [0.0, 1.5])  # segment 1 ready 1.5 s after segment 0 began
    np.testing.assert_allclose(held.t, [0.0, 1.0, 1.5, 2.5])
    np.testing.assert_allclose(arrivals, [0.0, 1.0, 2.5])
    np.testing.assert_allclose(held.x[1], held.x[2])  # node 1 repeated, at rest
    cut, arrivals = space_scheduled(reference, 1, [0.0, np.inf])  # segment 1 never ready: ends at node 1
    assert len(cut.t) == 2 and arrivals.tolist() == [0.0, 1.0]


def test_the_space_tracking_error_is_an_angle_and_a_distance():
    assert space_off_plan(np.array([0.03, 0.0, 0.04, 0.0, 0.003, 0.004])) == pytest.approx((0.05, 0.005))


@pytest.mark.slow
def test_a_3d_plan_replans_at_friction_0p4_end_to_end_with_typed_outcomes(space_plan, tmp_path, capsys):
    """`plan --hand fingerpro4` (a 34 deg turn about x: conftest's space_plan, planned once for the run), then
    `simulate --replan --sim-mu 0.4`: the run ends, sim.json records each replan with its reason, outcome and compute
    times; the friction estimate's fall starts them. A replan deadline out of its range first: exit 2 naming it, no
    sim.json."""
    plan = tmp_path / "plan"
    shutil.copytree(space_plan, plan)
    bad = "controller: {replan: {space_search_deadline_s: 0}}"  # bad input: exit 2 naming it, nothing written
    assert main(["simulate", str(plan), "--replan", "--config-text", bad]) == 2
    err = capsys.readouterr().err
    assert "space_search_deadline_s" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (plan / "sim.json").exists()
    assert main(["simulate", str(plan), "--replan", "--sim-mu", "0.4"]) == 0
    out = capsys.readouterr().out
    sim = json.loads((plan / "sim.json").read_text())
    assert sim["executor"] == "grasp-replan" and sim["conditions"]["sim_mu"] == 0.4
    replans = sim["replans"]
    assert replans and replans[0]["reason"] == "friction" and "replan at" in out
    outcomes = {o.name.lower() for o in ReplanOutcome}
    for event in replans:
        assert event["outcome"] in outcomes and event["compute_s"] > 0.0
        assert event["takes_effect_s"] >= event["time_s"]  # never before its compute time has passed
    # the run lasts the plan in effect: each hold while the planner ran lengthens it
    with np.load(plan / "sim.npz") as npz:
        assert npz["t"][-1] == pytest.approx(sim["duration_s"])
        assert npz["x"].shape[1] == 7 and npz["x_plan"].shape == npz["x"].shape
