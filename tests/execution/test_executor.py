"""One executor, chosen once (config.executor.Executor) and dispatched where the execution Diagram is
built: each executor's systems, the CLI's --executor (and its older spellings) and its bad input."""

import numpy as np
import pytest
from test_simulate import hold_plan_arrays, write_plan_dir

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, with_values
from trajectotree.config.executor import EXECUTORS, Executor, executor_of, parse_executor
from trajectotree.execution.control import ClosedLoopGraspController, GraspController
from trajectotree.execution.impedance import ImpedanceController
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.simulate import build_execution_diagram
from trajectotree.io import load_sim
from trajectotree.scene.plant import build_scene

HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)
CLOSED_LOOP_SYSTEMS = {
    "landing_reflex",
    "cone_friction",
    "contact_monitor",
    "object_monitor",
    "friction_estimator",
    "mass_estimator",
    "push_reflex",
}


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def system_names(diagram) -> set[str]:
    return {system.get_name() for system in diagram.GetSystems()}


@pytest.mark.parametrize(
    "executor, controller, kind",
    [
        (Executor.GRASP, "grasp_controller", GraspController),
        (Executor.GRASP_CLOSED_LOOP, "grasp_controller", ClosedLoopGraspController),
        (Executor.PAPER, "impedance_controller", ImpedanceController),
    ],
)
def test_each_executor_builds_its_own_systems(scene, executor, controller, kind):
    """The executor is dispatched once, where the Diagram is built: the closed loop's systems exist
    exactly for the closed-loop executors, and the open-loop grasp controller reads the state and the
    plan alone (grasp-replan, which needs a PlanResult: tests/execution/test_replanner_system.py)."""
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.2)
    execution = build_execution_diagram(reference, Config(), executor=executor)
    names = system_names(execution.executor.diagram)
    system = execution.executor.diagram.GetSubsystemByName(controller)
    assert type(system) is kind
    assert (CLOSED_LOOP_SYSTEMS <= names) == executor.closed_loop
    assert not (CLOSED_LOOP_SYSTEMS & names) or executor.closed_loop
    assert (execution.closed_loop_loggers is not None) == executor.closed_loop
    assert execution.controller == executor.controller
    if executor is Executor.GRASP:
        assert [system.get_input_port(i).get_name() for i in range(system.num_input_ports())] == [
            "box_state",
            "hand_state",
            "plan",
        ]


def test_the_zero_torque_executor_and_the_default(scene):
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.2)
    none = build_execution_diagram(reference, Config(), executor=Executor.NONE)
    assert "zero_torque" in system_names(none.executor.diagram) and none.controller == "none"
    paper = with_values(Config(), {"sim.controller": "paper"})
    default = build_execution_diagram(reference, paper)  # config.sim.controller, open loop
    assert "impedance_controller" in system_names(default.executor.diagram) and default.closed_loop_loggers is None


def test_executor_names_and_the_older_options():
    assert EXECUTORS == ("grasp", "grasp-closed-loop", "grasp-replan", "paper", "none")
    assert [parse_executor(name) for name in EXECUTORS] == list(Executor)
    assert executor_of("grasp") is Executor.GRASP and executor_of("paper") is Executor.PAPER
    assert executor_of("grasp", closed_loop=True) is Executor.GRASP_CLOSED_LOOP
    assert executor_of("grasp", closed_loop=True, replan=True) is Executor.GRASP_REPLAN
    assert executor_of("grasp", replan=True) is Executor.GRASP_REPLAN
    with pytest.raises(ConfigError, match="controller = 'paper': the closed loop runs around the grasp controller"):
        executor_of("paper", replan=True)
    with pytest.raises(ConfigError, match="controller = 'pid' is not a controller; valid: grasp, paper"):
        executor_of("pid")
    with pytest.raises(
        ConfigError,
        match="^executor = 'closed' is not an executor; valid: grasp, grasp-closed-loop, grasp-replan, paper, none$",
    ):
        parse_executor("closed")


@pytest.fixture
def plan_dir(tmp_path, scene):
    return write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), Config())


@pytest.mark.parametrize(
    "options, named",
    [
        (
            ["--executor", "grasp-open-loop"],
            "--executor = 'grasp-open-loop' is not an executor; valid: grasp, grasp-closed-loop, grasp-replan, "
            "paper, none",
        ),
        (["--executor", "paper", "--closed-loop"], "--executor paper names the whole executor: give it without "),
        (["--executor", "grasp", "--replan"], "without --replan"),
        (["--closed-loop", "--controller", "paper"], "controller = 'paper': the closed loop runs around the grasp"),
    ],
)
def test_simulate_refuses_an_executor_that_does_not_exist_and_writes_nothing(
    tmp_path, capsys, plan_dir, options, named
):
    options = [str(tmp_path / o) if o == "run.html" else o for o in options]
    assert main(["simulate", str(plan_dir), *options]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err and err.count("error:") == 1
    assert sorted(p.name for p in plan_dir.iterdir()) == ["plan.json", "plan.npz"]
    assert not (tmp_path / "run.html").exists()


def test_simulate_executor_is_the_closed_loop_option_by_its_name(plan_dir, tmp_path):
    """`--executor grasp-closed-loop` is the run `--closed-loop` makes, to the last bit."""
    assert main(["simulate", str(plan_dir), "--executor", "grasp-closed-loop", "--sim-mu", "0.5"]) == 0
    named = load_sim(plan_dir)
    assert named.closed_loop is not None
    assert main(["simulate", str(plan_dir), "--closed-loop", "--sim-mu", "0.5"]) == 0
    flagged = load_sim(plan_dir)
    for name in ("t", "x", "q", "f_W"):
        np.testing.assert_array_equal(getattr(named, name), getattr(flagged, name), err_msg=name)
    np.testing.assert_array_equal(named.closed_loop.mu_estimate, flagged.closed_loop.mu_estimate)
