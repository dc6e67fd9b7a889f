"""Run a plan closed loop in a Diagram of your own: your plant (built here from TrajectoTree's models, in a
world with less friction than the plan assumed), your Simulator and your Meshcat, with TrajectoTree's
executor (controller, monitors, estimators, reflexes; with --executor grasp-replan also the replanner,
which plans again from the measured state inside your Diagram) added by `tt.add_executor` and wired by
port name.

    python examples/closed_loop_in_your_diagram.py [--goal RAD] [--sim-mu MU] [--executor NAME] [--no-meshcat]
"""

import argparse
import dataclasses

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

import trajectotree as tt
from trajectotree.scene.plant import add_hand_and_box


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal", type=float, default=0.3, help="the box's final turn, rad")
    parser.add_argument("--sim-mu", type=float, default=0.5, help="your plant's friction (the plan assumes 0.7)")
    parser.add_argument("--executor", default="grasp-closed-loop", help="grasp-closed-loop or grasp-replan")
    parser.add_argument("--no-meshcat", action="store_true", help="run without a Meshcat")
    args = parser.parse_args()

    result = tt.plan(goal=args.goal)  # contact search + CITO at the paper's scene
    if not result.success:
        print(f"no plan: {result.status}")
        return 1
    config = result.config

    # Your Diagram: a plant of the hand and the box, in your world (its friction), and its SceneGraph.
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    world = dataclasses.replace(config.scene, mu=args.sim_mu)
    hand, box = add_hand_and_box(plant, world, scene_graph)
    plant.Finalize()

    # TrajectoTree's closed-loop executor for the plan, one system with named ports.
    executor = tt.add_executor(
        builder, plant, result, config, scene_graph=scene_graph, hand=hand, box=box, executor=args.executor
    )
    builder.Connect(plant.get_state_output_port(box), executor.GetInputPort("box_state"))
    builder.Connect(plant.get_state_output_port(hand), executor.GetInputPort("hand_state"))
    builder.Connect(plant.get_contact_results_output_port(), executor.GetInputPort("contact_results"))
    builder.Connect(plant.get_generalized_contact_forces_output_port(box), executor.GetInputPort("box_contact_forces"))
    builder.Connect(executor.GetOutputPort("actuation"), plant.get_actuation_input_port())
    meshcat = None
    if not args.no_meshcat:
        meshcat = Meshcat()
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        print(f"Meshcat: {meshcat.web_url()}")
    diagram = builder.Build()

    # Your Simulator, from the plan's first state (at rest).
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, box, result.trajectory.x[0])
    plant.SetPositions(plant_context, hand, result.trajectory.q[0])
    simulator = Simulator(diagram, context)
    executor.advance_to_end(simulator)  # to the plan's end and its settle time (a replan moves the end)

    x = plant.GetPositions(plant.GetMyContextFromRoot(simulator.get_context()), box)
    estimate = executor.GetOutputPort("mu_estimate").Eval(
        executor.diagram.GetMyContextFromRoot(simulator.get_context())
    )
    error = x - result.trajectory.x[-1]
    for event in executor.replans(simulator.get_context()):
        print(f"replan at {event.time_s:.2f} s ({event.reason.value}): {event.outcome.value}")
    print(
        f"after {simulator.get_context().get_time():.2f} s: box at x {x[0]:+.4f} m, y {x[1]:+.4f} m, "
        f"theta {x[2]:+.3f} rad "
        f"(goal {result.trajectory.x[-1][2]:+.3f}); error {1e3 * np.hypot(*error[:2]):.1f} mm, "
        f"{abs(error[2]):.3f} rad; friction estimate {estimate[0]:.3f} (world {args.sim_mu:g})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
