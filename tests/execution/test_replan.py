"""Replanning during execution (trajectotree.execution.replan): at a plan's nodes the closed loop's
estimates decide whether to plan again from the measured state; the run is one continuous log."""

import dataclasses
import json
import time

import numpy as np
import pytest

from trajectotree.config import Config, ConfigError, ReplanConfig
from trajectotree.execution.reference import Reference
from trajectotree.execution.replan import Phase, delayed, out_of_time, scheduled
from trajectotree.planning.planners import plan
from trajectotree.refusal import AtRoot, NoPlan, OnGrids, Refusal, RefusalKind
from trajectotree.results import ReplanEvent, ReplanOutcome, ReplanReason
from trajectotree.start import StartProblem, StartRefusal


def line_reference(segments: int, knots_per_segment: int = 3, dt: float = 0.1) -> Reference:
    """A reference whose object x is its knot index (fingertips and forces likewise), at rest at the nodes."""
    k = np.arange(segments * knots_per_segment + 1, dtype=float)
    zeros4 = np.zeros((len(k), 4, 2))
    return Reference(
        t=k * dt,
        x=np.column_stack([k, np.zeros_like(k), np.zeros_like(k)]),
        q=np.tile(k[:, None], (1, 8)),
        p_WF=zeros4 + k[:, None, None],
        v_WF=zeros4,
        f_W=zeros4 + 1.0,
        xdot=np.zeros((len(k), 3)),
    )


def test_a_segment_begins_no_earlier_than_it_is_ready_the_hand_holding_its_node():
    new = line_reference(3)  # segments of 0.3 s: nodes at knots 0, 3, 6, 9
    held, arrivals = scheduled(new, 3, [0.0, 0.1, 1.0])  # segment 2 ready 0.4 s after node 2 is reached
    np.testing.assert_allclose(arrivals, [0.0, 0.3, 0.6, 1.3])
    i = np.searchsorted(held.t, 0.6)
    np.testing.assert_allclose(held.t[i : i + 2], [0.6, 1.0])  # node 2 (knot 6) held from 0.6 s to 1.0 s
    np.testing.assert_array_equal(held.x[i : i + 2, 0], [6.0, 6.0])
    np.testing.assert_allclose(held.object_pose_at([0.8])[0], [6.0, 0.0, 0.0])
    np.testing.assert_allclose(held.object_pose_at([1.15])[0, 0], 7.5)  # then segment 2 as planned, 0.4 s late
    assert np.all(np.diff(held.t) > 0)


def test_a_plan_is_executed_up_to_its_first_segment_that_never_is_ready():
    held, arrivals = scheduled(line_reference(3), 3, [0.0, 0.2, np.inf])
    np.testing.assert_allclose(arrivals, [0.0, 0.3, 0.6])
    assert held.x[-1, 0] == 6.0 and held.t[-1] == pytest.approx(0.6)


def test_the_old_plan_resumes_after_the_hold_while_the_planner_ran():
    old = line_reference(3)
    later = delayed(old, 0.3, 0.25)  # held at node 1 while a replan that gave nothing ran 0.25 s
    np.testing.assert_allclose(later.object_pose_at([0.2, 0.3, 0.45, 0.55, 0.65])[:, 0], [2, 3, 3, 3, 4])
    assert later.duration == pytest.approx(old.duration + 0.25)
    assert Phase((0.3, 0.6), 0.9).after(0.3, 0.25) == Phase((0.85,), 1.15)


def test_a_replan_without_a_plan_says_why_as_a_type_and_as_text():
    deadline = Refusal(RefusalKind.TIME_BUDGET, limit=0.5)
    grid = NoPlan(1, 1, 0, None, AtRoot((0.0, 0.1, 0.2, 0.3), deadline), 0.27, ())
    assert out_of_time(deadline) and out_of_time(grid) and out_of_time(OnGrids(((0.02, grid),)))
    assert not out_of_time(Refusal(RefusalKind.TREE_EXHAUSTED, count=10))
    event = ReplanEvent(2.4, ReplanReason.FRICTION, 0.39, 0.05, 0.5, 2.9, ReplanOutcome.SEARCH_DEADLINE, str(grid))
    event = dataclasses.replace(event, refusal=grid)
    saved = event.to_json()
    assert not event.planned and saved["planned"] is False and saved["outcome"] == "search_deadline"
    assert saved["refusal"]["kind"] == "no_plan" and "time budget exhausted (0.5 s)" in saved["status"]
    start = StartRefusal(StartProblem.MOVING, value=0.98, limit=0.1)
    assert dataclasses.replace(event, refusal=start).to_json()["refusal"] == {
        "kind": "start",
        "problem": "moving",
        "value": 0.98,
        "limit": 0.1,
    }
    json.dumps(saved, allow_nan=False)  # sim.json has no NaN


@pytest.mark.parametrize(
    "field, value",
    [
        ("theta_error", 0.0),
        ("position_error", -0.001),
        ("friction_drop", 0.0),
        ("search_deadline_s", 0),
        ("first_segment_deadline_s", -1.0),
    ],
)
def test_a_replan_threshold_at_or_below_zero_is_refused(field, value):
    with pytest.raises(ConfigError, match=rf"controller.replan.{field} = .* is out of range; valid range: \(0"):
        ReplanConfig(**{field: value})


@pytest.fixture(scope="module")
def moved_start():
    """Node 7 of the search's plan for 0.9 rad, the object 5 mm right and 0.1 rad further turned and the
    fingers re-solved onto the same contacts: a state measured off the plan. Node 4, used before the
    fingers were kept apart, is now a grasp whose finger 2 cannot reach its contact so moved; node 5
    reaches, but from it the replan at friction 0.6 finds no plan (finger 0 out of reach, the others
    no closure)."""
    from trajectotree.geometry import box_to_world, rotation_2d
    from trajectotree.scene.dynamics import HandModel
    from trajectotree.scene.plant import build_scene
    from trajectotree.search.tree import find_contact_plan
    from trajectotree.start import StartState

    config = Config()
    scene = build_scene(config.scene)
    node = find_contact_plan(scene, 0.9, config.search).nodes[7]
    pose = node.object_pose + np.array([0.005, 0.0, 0.1])
    hand = HandModel.from_scene(scene)
    tips = [box_to_world(pose, node.p_BC[i]) + scene.tip_radius * rotation_2d(pose[2]) @ node.n_B[i] for i in range(4)]
    q = np.concatenate([hand.ik(i, tips[i]) for i in range(4)])
    return scene, StartState(object_pose=tuple(pose), q=tuple(q))


@pytest.mark.slow
def test_a_replanned_plan_begins_at_the_measured_state_its_first_segment_ready_first(moved_start):
    from trajectotree.execution.replan import PlanePlanning, replan

    scene, start = moved_start
    config = Config()
    old = plan(goal=1.2, config=config, segment_workers=1)  # the plan whose goal the replan keeps
    # deadlines no busy machine meets too late: this test is about the plan, not the time it takes
    rules = ReplanConfig(search_deadline_s=30.0, first_segment_deadline_s=300.0)
    executing = dataclasses.replace(old.config, controller=dataclasses.replace(old.config.controller, replan=rules))
    planning = PlanePlanning(old, executing, scene, segment_workers=1)
    event, solved = replan(planning, start, 4.8, ReplanReason.TRACKING, 0.6, 0.05)
    new = solved.new
    assert event.outcome is ReplanOutcome.PLANNED and event.planned, event.status
    np.testing.assert_allclose(new.trajectory.x[0], start.object_pose, atol=1e-9)  # the measured state
    np.testing.assert_allclose(new.trajectory.q[0], start.q, atol=1e-9)
    assert new.trajectory.x[-1, 2] == pytest.approx(1.2, abs=1e-9)  # the old plan's goal
    assert new.config.scene.mu == 0.6 and new.config.search.time_budget_s == rules.search_deadline_s
    assert new.config.search.budget_clock == "wall"  # a deadline in the world, which does not wait
    ready = np.array(event.segment_ready_s)
    assert len(ready) == len(new.contact_plan.nodes) - 1 and np.all(np.isfinite(ready))
    assert event.latency_s == ready[0] and np.all(ready[1:] > ready[0]) and event.compute_s >= ready.max()
    assert event.search_s < event.latency_s
    # Solved first segment first, it is the plan solved at once from the same contacts (independent segments).
    at_once = plan(goal=old.config.goal, start=start, config=new.config, contact_plan=new.contact_plan)
    assert at_once.segment_ready_s == ()
    for name in ("x", "q", "f_W"):
        np.testing.assert_allclose(getattr(new.trajectory, name), getattr(at_once.trajectory, name), atol=1e-9)


@pytest.mark.parametrize(
    "options, named",
    [
        (["--config", "THRESHOLD"], "controller.replan.theta_error = 0.0 is out of range; valid range: (0, 3.14"),
        (
            ["--friction-floor", "0"],
            "--friction-floor (controller.estimators.friction_floor) = 0.0 is out of range; valid range: (0, 1]",
        ),
        (["--controller", "paper"], "controller = 'paper': the closed loop runs around the grasp"),
    ],
)
def test_simulate_replan_refuses_bad_options_naming_the_value_and_writes_nothing(tmp_path, capsys, options, named):
    from test_simulate import hold_plan_arrays, write_plan_dir

    from trajectotree.cli import main
    from trajectotree.scene.plant import build_scene

    config = Config()
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(build_scene(config.scene), 0.3), config)
    bad = tmp_path / "threshold.yaml"
    bad.write_text("sim:\n  replan:\n    theta_error: 0\n")
    options = [{"THRESHOLD": str(bad), "run.html": str(tmp_path / "run.html")}.get(o, o) for o in options]
    assert main(["simulate", str(plan_dir), "--replan", *options]) == 2
    assert named in capsys.readouterr().err
    assert sorted(p.name for p in plan_dir.iterdir()) == ["plan.json", "plan.npz"]
    assert not (tmp_path / "run.html").exists()


def test_a_first_segment_past_its_deadline_is_not_retried_and_nothing_after_it_is_solved():
    from trajectotree.planning.keyframes import solve_first_segment_first
    from trajectotree.scene.plant import build_scene
    from trajectotree.search.tree import find_contact_plan

    config = Config()
    config = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    scene = build_scene(config.scene)
    contact_plan = find_contact_plan(scene, 0.3, config.search)
    since = time.perf_counter()
    pieces, attempts, ready = solve_first_segment_first(
        contact_plan, config, scene=scene, since=since, first_deadline_s=1e-3
    )
    assert [p.success for p in pieces] == [False] and len(attempts[0]) == 1  # IPOPT stopped, no retry after
    assert 0 < ready[0] < time.perf_counter() - since and ready[1:] == (np.inf,)
