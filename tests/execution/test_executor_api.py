"""trajectotree.add_executor: the executor as one system of a caller's Diagram, wired by port name, and
the example that runs a plan closed loop in a Diagram, Simulator and Meshcat of its own."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder

import trajectotree as tt
from trajectotree.config import Config, ConfigError
from trajectotree.execution import executor as executor_module
from trajectotree.execution.reference import static_hold_reference
from trajectotree.scene.plant import add_hand_and_box, build_scene

EXAMPLE = Path(__file__).parents[2] / "examples" / "closed_loop_in_your_diagram.py"
HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)


def callers_diagram(config: Config):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    hand, box = add_hand_and_box(plant, config.scene, scene_graph)
    plant.Finalize()
    return builder, plant, scene_graph, hand, box


def port_names(system, kind: str) -> dict[str, int]:
    count = getattr(system, f"num_{kind}_ports")()
    ports = [getattr(system, f"get_{kind}_port")(i) for i in range(count)]
    return {port.get_name(): port.size() for port in ports}


@pytest.mark.parametrize("executor", ["grasp", "grasp-closed-loop", "paper", "none"])
def test_the_executor_has_its_ports_by_name_and_its_doc_names_each(executor):
    config = Config()
    builder, plant, scene_graph, hand, box = callers_diagram(config)
    reference = static_hold_reference(build_scene(), HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.2)
    added = tt.add_executor(
        builder, plant, reference, config, scene_graph=scene_graph, hand=hand, box=box, executor=executor
    )
    inputs, outputs = port_names(added.diagram, "input"), port_names(added.diagram, "output")
    assert outputs["actuation"] == plant.num_actuators() == 8
    expected = {"none": {}, "paper": {"hand_state": 16}, "grasp": {"box_state": 6, "hand_state": 16}}
    closed = {"box_state": 6, "hand_state": 16, "contact_results": 0, "box_contact_forces": 3}
    assert inputs == expected.get(executor, closed)
    if executor == "grasp-closed-loop":
        assert set(outputs) == {"actuation", "plan", *executor_module.CLOSED_LOOP_OUTPUTS}
        assert outputs["mu_estimate"] == 1 and outputs["disturbance"] == 2 and outputs["tracking_error"] == 3
    doc = executor_module.__doc__
    for name in {*inputs, *outputs}:
        assert f"`{name}`" in doc, name
    assert added.duration == pytest.approx(reference.duration + config.sim.settle_time)


def test_add_executor_refuses_a_name_that_is_no_executor_and_a_reference_without_config():
    config = Config()
    builder, plant, scene_graph, hand, box = callers_diagram(config)
    reference = static_hold_reference(build_scene(), HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.2)
    kwargs = {"scene_graph": scene_graph, "hand": hand, "box": box}
    with pytest.raises(ConfigError, match="executor = 'mpc' is not an executor; valid: grasp, grasp-closed-loop"):
        tt.add_executor(builder, plant, reference, config, executor="mpc", **kwargs)
    with pytest.raises(ConfigError, match="give config= with a Reference"):
        tt.add_executor(builder, plant, reference, **kwargs)


@pytest.mark.slow
def test_the_example_runs_a_plan_closed_loop_in_its_own_diagram_simulator_and_meshcat():
    """The example plans, builds its own plant (friction 0.5 against the plan's 0.7), Meshcat and
    Simulator, wires the closed-loop executor by port name and ends on the goal."""
    done = subprocess.run([sys.executable, str(EXAMPLE)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Meshcat: http" in done.stdout
    match = re.search(r"error ([\d.]+) mm, ([\d.]+) rad; friction estimate ([\d.]+) \(world 0.5\)", done.stdout)
    assert match, done.stdout
    millimetres, radians, estimate = (float(v) for v in match.groups())
    assert millimetres < 5.0 and radians < 0.05 and 0.2 <= estimate <= 0.7
