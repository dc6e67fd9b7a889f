"""Replanning from the next node (trajectotree.execution.replan, issue 34's replans that cost no hold): the hand
goes on along its plan while the planner runs from the plan's next node; a new plan takes effect at that node,
never before its measured compute time has passed, and a refused one leaves the old plan going on unstalled."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from test_replan import line_reference

import trajectotree as tt
from trajectotree.config import Config, with_values
from trajectotree.config.executor import Executor
from trajectotree.execution.in_effect import plan_in_effect
from trajectotree.execution.reference import Reference, reference_from_plan
from trajectotree.execution.replan import Phase, Replanning, Swap, joined, node_state
from trajectotree.execution.simulate import build_execution_diagram
from trajectotree.results import ReplanOutcome, ReplanReason
from trajectotree.scene.plant import build_scene


def shifted(reference: Reference, by: float) -> Reference:
    """`reference` with its object x, joint angles and fingertips `by` further (a plan from a later node)."""
    return dataclasses.replace(reference, x=reference.x + [by, 0.0, 0.0], q=reference.q + by, p_WF=reference.p_WF + by)


def test_a_new_plan_joins_the_old_at_the_node_it_starts_from():
    old = line_reference(3)  # segments of 0.3 s; object x = knot index
    start = node_state(old, 0.3)  # node 1's planned state: the new plan's first knot
    np.testing.assert_allclose([*start.object_pose, *start.q], [3.0, 0.0, 0.0] + [3.0] * 8, atol=1e-12)
    assert not any(start.object_velocity)  # at rest
    new = shifted(line_reference(2), 3.0)
    followed = joined(old, 0.3, new)
    np.testing.assert_allclose(followed.object_pose_at([0.1, 0.3, 0.45, 0.9])[:, 0], [1.0, 3.0, 4.5, 9.0])
    assert followed.duration == pytest.approx(0.3 + new.duration) and np.all(np.diff(followed.t) > 0)
    np.testing.assert_allclose(followed.q[followed.t <= 0.3 + 1e-9], old.q[old.t <= 0.3 + 1e-9])


def test_a_swap_decided_at_a_node_takes_effect_at_the_next_node_not_before():
    config, scene = Config(), build_scene()
    old = plan_in_effect(line_reference(3), config, scene, 0.7)
    new = plan_in_effect(joined(old.reference, 0.6, shifted(line_reference(1), 6.0)), config, scene, 0.4, 1)
    assumed = dataclasses.replace(config.scene, mu=0.4)
    state = Replanning(old, Phase((0.6,)), config.scene, (), Swap(0.6, new, Phase(()), assumed))
    assert state.at(0.598) is state  # the control period before the node: the old plan still
    swapped = state.at(0.6)
    assert swapped.plan is new and swapped.phase == Phase(()) and swapped.assumed.mu == 0.4
    assert swapped.pending is None and swapped.at(0.7) is swapped


def test_the_next_node_is_the_next_check_or_the_end_of_a_plan_that_ends_short():
    config, scene = Config(), build_scene()
    state = Replanning(plan_in_effect(line_reference(3), config, scene, 0.7), Phase((0.3, 0.6)), config.scene)
    assert state.next_node_s(Phase((0.6,))) == 0.6
    assert state.next_node_s(Phase((), 1.1)) == pytest.approx(0.9)  # its last node, before the goal
    assert state.next_node_s(Phase(())) is None  # the goal: nothing left to plan


@pytest.fixture(scope="module")
def three_segments():
    """A three-segment plan (0.45 rad) of 2.4 s segments (cito.dt 0.2: the planner has 2.4 s of simulated
    time to the next node, which a loaded machine meets), executed with a tracking threshold every run
    exceeds at node 1 (a replan at 2.4 s, from node 2 at 4.8 s) and at most one replan."""
    result = tt.plan(goal=0.45, config=with_values(Config(), {"search.num_nodes": 4, "cito.dt": 0.2}))
    assert result.success, result.status
    tight = {
        "controller.replan.theta_error": 1e-4,
        "controller.replan.position_error": 1e-5,
        "controller.replan.max_replans": 1,
        # the deadlines a 2.4 s segment allows, not the 1.2 s ones' defaults: the test is about the next node
        "controller.replan.search_deadline_s": 1.0,
        "controller.replan.first_segment_deadline_s": 2.0,
    }
    return result, with_values(result.config, tight)


def executed(plan, config):
    """The execution Diagram of `plan` replanned with `config`, its simulator and the executor."""
    reference = reference_from_plan(plan, build_scene(config.scene))
    execution = build_execution_diagram(reference, config, executor=Executor.GRASP_REPLAN, plan=plan)
    simulator = Simulator(execution.diagram, execution.initial_context(reference))
    return reference, simulator, execution.executor


def plan_version(executor, simulator) -> int:
    context = executor.diagram.GetMyContextFromRoot(simulator.get_context())
    return executor.GetOutputPort("plan").Eval(context).version


@pytest.mark.slow
def test_a_replan_from_the_next_node_takes_effect_there_after_its_compute_time(three_segments):
    plan, config = three_segments
    reference, simulator, executor = executed(plan, config)
    simulator.AdvanceTo(4.79)  # decided at node 1 (2.4 s); node 2 not reached yet
    (event,) = executor.replans(simulator.get_context())
    assert event.reason is ReplanReason.TRACKING and event.time_s == pytest.approx(2.4)
    assert event.start_s == pytest.approx(4.8), event.to_json()  # from node 2's planned state
    assert event.outcome is ReplanOutcome.PLANNED, event.status
    # honest timing: the new plan waits for the node, which comes after its measured compute time
    assert event.takes_effect_s == event.start_s and event.time_s + event.latency_s <= event.takes_effect_s
    assert plan_version(executor, simulator) == 0  # meanwhile the hand goes on along the old plan
    simulator.AdvanceTo(4.81)
    assert plan_version(executor, simulator) == 1
    executor.advance_to_end(simulator)
    context = simulator.get_context()
    followed = executor.reference_in_effect(context)
    before = np.linspace(0.0, 4.8, 60)  # the old plan up to node 2, as planned: no hold
    np.testing.assert_allclose(followed.object_pose_at(before), reference.object_pose_at(before), atol=1e-12)
    assert followed.x[-1, 2] == pytest.approx(0.45, abs=1e-9)  # the new plan reaches the goal
    assert context.get_time() == pytest.approx(followed.duration + config.sim.settle_time)


@pytest.mark.slow
def test_a_replan_refused_at_the_next_node_leaves_the_plan_going_on_unstalled(three_segments):
    plan, config = three_segments
    # the search's time to the node all but kept for the first segment: it refuses at once
    config = with_values(config, {"controller.replan.first_segment_reserve_s": 59.0})
    reference, simulator, executor = executed(plan, config)
    executor.advance_to_end(simulator)
    context = simulator.get_context()
    (event,) = executor.replans(context)
    assert event.outcome is ReplanOutcome.SEARCH_DEADLINE and not event.planned, event.status
    assert event.start_s == pytest.approx(4.8) and event.takes_effect_s == event.time_s  # nothing held
    followed = executor.reference_in_effect(context)  # the plan as planned, neither held nor swapped
    for name in ("t", "x", "q", "f_W"):
        np.testing.assert_array_equal(getattr(followed, name), getattr(reference, name))
    assert plan_version(executor, simulator) == 0
    assert context.get_time() == pytest.approx(reference.duration + config.sim.settle_time)
