"""The replanner as a system (trajectotree.execution.replan.Replanner): one Diagram and one Simulator run a
replanned execution; the replanner's plan output feeds every system that follows the plan, a replan swaps
it in at the update at a node, and the plan in effect holds the measured state while the planner ran."""

import json

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

import trajectotree as tt
from trajectotree.config import Config, ConfigError, with_values
from trajectotree.config.executor import Executor
from trajectotree.execution.reference import reference_from_plan, static_hold_reference
from trajectotree.execution.replan import HOLD_RAMP, Phase
from trajectotree.execution.simulate import build_execution_diagram
from trajectotree.execution.world import Conditions
from trajectotree.results import ReplanReason
from trajectotree.scene.plant import build_scene

FOLLOWERS = ("grasp_controller", "landing_reflex", "contact_monitor", "friction_estimator")


def test_a_check_falls_due_at_the_first_update_at_or_after_its_node():
    phase = Phase((1.2, 2.4), 3.0)
    assert phase.due(1.198) == (False, None, phase)
    assert phase.due(1.2) == (True, None, Phase((2.4,), 3.0))
    assert phase.due(1.202) == (True, None, Phase((2.4,), 3.0))  # a control period late: still checked once
    assert phase.due(3.0) == (True, ReplanReason.PLAN_ENDS_SHORT, Phase((), None))


def test_grasp_replan_needs_the_plan_result_whose_goal_it_keeps():
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.systems.framework import DiagramBuilder

    from trajectotree.scene.plant import add_hand_and_box

    config = Config()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    hand, box = add_hand_and_box(plant, config.scene, scene_graph)
    plant.Finalize()
    reference = static_hold_reference(build_scene(), (0.56, 0.14, 0.26, 0.44), min_normal_force=1.0, duration=0.2)
    with pytest.raises(ConfigError, match=r"add_executor\(executor='grasp-replan'\): give the PlanResult"):
        tt.add_executor(
            builder, plant, reference, config, scene_graph=scene_graph, hand=hand, box=box, executor="grasp-replan"
        )


@pytest.fixture(scope="module")
def short_plan():
    """A two-segment plan (0.3 rad, 2.4 s), executed with a tracking threshold every run exceeds at its node
    (a replan at 1.2 s), planned from the measured state with the hand holding (the next node is the goal:
    tests/execution/test_replan_ahead.py plans from it) and at most one replan."""
    result = tt.plan(goal=0.3, config=with_values(Config(), {"search.num_nodes": 3}))
    assert result.success, result.status
    tight = {
        "controller.replan.theta_error": 1e-4,
        "controller.replan.position_error": 1e-5,
        "controller.replan.max_replans": 1,
        "controller.replan.measured_start_on_error": True,
    }
    return result, with_values(result.config, tight)


@pytest.mark.slow
def test_the_replanner_feeds_every_system_that_follows_the_plan(short_plan):
    plan, config = short_plan
    reference = reference_from_plan(plan, build_scene(config.scene))
    execution = build_execution_diagram(reference, config, executor=Executor.GRASP_REPLAN, plan=plan)
    diagram = execution.executor.diagram
    replanner = diagram.GetSubsystemByName("replanner")
    assert replanner is execution.executor.replanner
    inputs = [replanner.get_input_port(i).get_name() for i in range(replanner.num_input_ports())]
    assert inputs == ["box_state", "hand_state", "mu_estimate", "mass_estimate", "tracking_error", "in_contact"]
    connections = diagram.connection_map()
    for name in FOLLOWERS:
        follower = diagram.GetSubsystemByName(name)
        source, port = connections[(follower, follower.GetInputPort("plan").get_index())]
        assert source is replanner and source.get_output_port(port).get_name() == "plan", name
    assert "plan_in_effect" not in {s.get_name() for s in diagram.GetSystems()}  # no second source of the plan


@pytest.mark.slow
def test_a_replan_swaps_the_plan_in_one_simulator_holding_while_the_planner_ran(short_plan):
    plan, config = short_plan
    reference = reference_from_plan(plan, build_scene(config.scene))
    execution = build_execution_diagram(
        reference, config, executor=Executor.GRASP_REPLAN, plan=plan, conditions=Conditions(mu=0.3)
    )
    simulator = Simulator(execution.diagram, execution.initial_context(reference))
    execution.executor.advance_to_end(simulator)
    context = simulator.get_context()
    (event,) = execution.executor.replans(context)
    assert event.reason is ReplanReason.TRACKING and event.time_s == pytest.approx(1.2)  # at the node's update
    assert event.takes_effect_s == pytest.approx(event.time_s + event.latency_s)
    followed = execution.executor.reference_in_effect(context)
    # the one Simulator ran to the end of the plan in effect, which the swap moved (by the hold at least)
    assert context.get_time() == pytest.approx(followed.duration + config.sim.settle_time)
    if not event.planned:  # the old plan resumed after the hold
        assert followed.duration == pytest.approx(reference.duration + event.latency_s)
    # every follower reads the swapped plan: the executor's plan output is version 1, the replanner's state
    in_effect = execution.executor.GetOutputPort("plan").Eval(execution.executor.diagram.GetMyContextFromRoot(context))
    assert in_effect.version == 1 and in_effect.reference is followed
    # the old plan up to the node, then the node's pose held while the planner ran
    before = np.linspace(0.0, event.time_s, 50)
    np.testing.assert_allclose(followed.object_pose_at(before), reference.object_pose_at(before), atol=1e-12)
    ramp = min(HOLD_RAMP, 0.5 * event.latency_s) if event.planned else 0.0  # to the measured pose
    poses = followed.object_pose_at(np.linspace(event.time_s + ramp, event.takes_effect_s, 20))
    np.testing.assert_allclose(poses, poses[:1].repeat(len(poses), axis=0), atol=1e-12)


@pytest.mark.slow
def test_simulate_replans_and_writes_its_playback_and_run(tmp_path, short_plan, capsys):
    """`simulate --executor grasp-replan --html` (refused before the replanner was a system) writes the
    run and its playback; exit 0."""
    from trajectotree.cli import main
    from trajectotree.io import save_plan

    plan, _ = short_plan
    save_plan(plan, tmp_path / "plan")
    tight = (
        "controller: {replan: {theta_error: 0.0001, position_error: 0.00001, max_replans: 1, "
        "measured_start_on_error: true}}"
    )
    html = tmp_path / "run.html"
    options = ["--executor", "grasp-replan", "--sim-mu", "0.3", "--config-text", tight, "--html", str(html)]
    assert main(["simulate", str(tmp_path / "plan"), *options, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert len(summary["replans"]) == 1 and summary["replans"][0]["reason"] == "tracking"
    # one log: the phase-by-phase runs logged the node twice (1.2 s and 1e-16 s later, the poses apart), read
    # as an object at 9e8 m/s, and this run ended "diverged" at the replan
    assert summary["outcome"] != "diverged" and summary["diverged_at_s"] is None
    t = np.load(tmp_path / "plan" / "sim.npz")["t"]
    assert np.all(np.diff(t) > 1e-6)
    assert html.stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "plan").iterdir()) == ["plan.json", "plan.npz", "sim.json", "sim.npz"]


@pytest.mark.slow
def test_add_executor_adds_the_replanner_with_the_closed_loops_ports_and_the_plan(short_plan):
    from test_executor_api import callers_diagram, port_names

    from trajectotree.execution import executor as executor_module

    plan, config = short_plan
    builder, plant, scene_graph, hand, box = callers_diagram(config)
    added = tt.add_executor(
        builder, plant, plan, config, scene_graph=scene_graph, hand=hand, box=box, executor="grasp-replan"
    )
    inputs, outputs = port_names(added.diagram, "input"), port_names(added.diagram, "output")
    assert inputs == {"box_state": 6, "hand_state": 16, "contact_results": 0, "box_contact_forces": 3}
    assert set(outputs) == {"actuation", "plan", *executor_module.CLOSED_LOOP_OUTPUTS}
    for name in {*inputs, *outputs}:
        assert f"`{name}`" in executor_module.__doc__ and f"`{name}`" in tt.add_executor.__doc__, name
    assert added.replanner is not None and added.duration == pytest.approx(2.4 + config.sim.settle_time)


def test_bench_replan_compares_trees_only_on_the_same_saved_plans():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).parents[2] / "scripts" / "bench_replan.py"
    done = subprocess.run(
        [sys.executable, str(script), "--compare", "/tmp"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2 and "--compare needs --plan-dirs" in done.stderr
