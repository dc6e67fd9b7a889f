"""Executing a plan in a full-dynamics Drake simulation (paper Sec. III-D, IV-D).

The execution Diagram: a discrete MultibodyPlant with the hand and box from
models/ (point contact between fingertip spheres, links and the box, friction
from the config, gravity -y), reference sources from the plan (fingertip
positions, velocities and forces, held at their last value for
SimConfig.settle_time after the plan ends), a controller (the object-level
GraspController, default, or eq. 20's ImpedanceController: the `Executor` chosen, one Diagram of its own,
trajectotree.execution.executor.add_executor; grasp-replan's holds the Replanner too, and its run lasts
until the end of the plan in effect: trajectotree.execution.replan),
loggers of the plant state and of each finger's simulated force on the box
(`FingertipForces`) and, optionally, a Meshcat visualizer. A run records a
`SimLog` (the logs beside the plan at the same times), which
`trajectotree.execution.metrics.evaluate` turns into the `SimResult` the functions here return.

`Conditions` (trajectotree.execution.world) change the simulated world only, never what the
controller assumes: the friction coefficient, the box mass and a push.

The run starts in the plan's initial state (x_0, q_0, at rest). Fingers collide with
each other like any other bodies (only each finger's own adjacent links are filtered,
as MultibodyPlant does for bodies joined by a joint): the planners keep them apart
(search.finger_clearance, CITO's finger rows) and the physics check measures it.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    ContactResults,
    MultibodyPlantConfig,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem, TriggerType
from pydrake.systems.primitives import LogVectorOutput

from trajectotree.config import Config
from trajectotree.config.executor import Executor
from trajectotree.execution import force_arrows, meshcat_scene, metrics, playback_page
from trajectotree.execution.executor import CLOSED_LOOP_OUTPUTS, ExecutorSystems, add_executor, connect_executor
from trajectotree.execution.reference import Reference
from trajectotree.execution.world import NOMINAL, Conditions, PushSource
from trajectotree.figures.legend import arrow_newtons_per_cm
from trajectotree.results import ClosedLoopLog, PlanResult, SimLog, SimResult
from trajectotree.scene.hand import HandDescription, finger_bodies, hand_file, read_hand
from trajectotree.scene.plant import add_hand_and_box


class FingertipForces(LeafSystem):
    """Input port `contact_results` (the plant's); output port `f_W` (2F, finger-major
    (x, y)): the force of each finger's second link (fingertip sphere and link, with a tip body
    welded to it: hand.finger_bodies) on the box, in W, summed over its point contacts."""

    def __init__(self, plant, hand, box, description: HandDescription):
        super().__init__()
        self._num_fingers = description.num_fingers
        self._finger_of_body = {
            body.index(): i for i, f in enumerate(description.fingers) for body in finger_bodies(plant, hand, f)[1:]
        }
        self._box_body = plant.GetBodyByName("box", box).index()
        self.contact_results_port = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.DeclareVectorOutputPort("f_W", 2 * self._num_fingers, self.CalcForces)

    def CalcForces(self, context, output):
        results = self.contact_results_port.Eval(context)
        f_W = np.zeros((self._num_fingers, 2))
        for k in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(k)
            a, b = info.bodyA_index(), info.bodyB_index()
            f_on_b = info.contact_force()[:2]  # the force on body B, in W
            if b == self._box_body and a in self._finger_of_body:
                f_W[self._finger_of_body[a]] += f_on_b
            elif a == self._box_body and b in self._finger_of_body:
                f_W[self._finger_of_body[b]] -= f_on_b
        output.SetFromVector(f_W.ravel())


@dataclass
class ExecutionDiagram:
    diagram: object
    plant: object
    hand: object  # ModelInstanceIndex
    box: object  # ModelInstanceIndex
    hand_description: HandDescription  # the hand as data, read from this plant
    state_logger: object  # VectorLogSink of the plant's full state
    force_logger: object  # VectorLogSink of FingertipForces (2F)
    visualizer: object | None  # MeshcatVisualizer or None
    controller: str  # "grasp", "paper" or "none" (uncontrolled)
    # closed loop: {ClosedLoopLog field: VectorLogSink of the output port of that name}; open loop: None
    closed_loop_loggers: dict | None = None
    executor: ExecutorSystems | None = None  # the executor's Diagram (its ports: trajectotree.execution.executor)

    def end_s(self, context) -> float:
        """s, when the run ends in the root `context`: the plan's length and the settle time (a replanned
        run's: the plan in effect's, which a replan moves)."""
        return self.executor.end_s(context)

    def initial_context(self, reference: Reference):
        """A context in the plan's first state: object pose x_0, joint angles q_0, at rest."""
        context = self.diagram.CreateDefaultContext()
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        self.plant.SetPositions(plant_context, self.box, reference.x[0])
        self.plant.SetPositions(plant_context, self.hand, reference.q[0])
        return context


def build_execution_diagram(
    reference: Reference,
    config: Config,
    *,
    executor: Executor | None = None,
    meshcat: Meshcat | None = None,
    conditions: Conditions = NOMINAL,
    plan: PlanResult | None = None,
    segment_workers: int | None = None,
) -> ExecutionDiagram:
    """The Diagram that executes `reference` with `executor` (None: config.sim.controller, open loop)
    in the world `conditions` describe; a closed-loop executor adds the monitors, the estimators and
    the reflexes around the grasp controller (trajectotree.execution.executor) and their loggers, and
    grasp-replan the Replanner of `plan` (the PlanResult of `reference`, whose goal it keeps; the later
    segments of a new plan on `segment_workers`)."""
    executor = Executor(config.sim.controller) if executor is None else executor
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    hand, box = add_hand_and_box(plant, conditions.scene(config.scene), scene_graph)
    plant.Finalize()
    description = read_hand(plant, scene_graph, hand, hand_file(config.scene.hand))
    added = add_executor(
        builder,
        plant,
        reference if plan is None else plan,
        config,
        scene_graph=scene_graph,
        hand=hand,
        box=box,
        executor=executor,
        segment_workers=segment_workers,
    )
    connect_executor(builder, added, plant, hand, box)
    if conditions.push is not None:
        push = builder.AddNamedSystem("push", PushSource(plant, box, conditions.push))
        builder.Connect(push.spatial_forces_port, plant.get_applied_spatial_force_input_port())
    triggers = {TriggerType.kPeriodic, TriggerType.kForced}
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, triggers, config.sim.log_period)
    forces = builder.AddNamedSystem("fingertip_forces", FingertipForces(plant, hand, box, description))
    builder.Connect(plant.get_contact_results_output_port(), forces.contact_results_port)
    force_logger = LogVectorOutput(forces.get_output_port(), builder, triggers, config.sim.log_period)
    closed_loop_loggers = None
    if executor.closed_loop:
        closed_loop_loggers = {
            name: LogVectorOutput(added.GetOutputPort(name), builder, triggers, config.sim.log_period)
            for name in CLOSED_LOOP_OUTPUTS
        }
    visualizer = None
    if meshcat is not None:
        visualizer = meshcat_scene.add_visualizer(builder, plant, scene_graph, hand, description, meshcat)
        force_arrows.add_force_arrows_system(
            builder, plant, scene_graph, hand, description, meshcat, forces.get_output_port(), arrow_scale(reference)
        )
    return ExecutionDiagram(
        diagram=builder.Build(),
        plant=plant,
        hand=hand,
        box=box,
        hand_description=description,
        state_logger=state_logger,
        force_logger=force_logger,
        visualizer=visualizer,
        controller=executor.controller,
        closed_loop_loggers=closed_loop_loggers,
        executor=added,
    )


def arrow_scale(reference: Reference) -> float:
    """The force arrows' scale (N per cm) of a run of `reference`: set by the plan's forces, so that
    the playback and the GIF of one plan share it and a dropped box's squeeze does not shrink it."""
    return arrow_newtons_per_cm(reference.f_W)


def split_state_log(execution: ExecutionDiagram, log) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T,), object pose (T, 3), joint angles (T, 2F), finger-major) from the plant-state log."""
    plant = execution.plant
    box_start = plant.GetJointByName("box_planar").position_start()
    hand_q = [
        plant.GetJointByName(name, execution.hand).position_start() for name in execution.hand_description.joint_names
    ]
    data = log.data()
    return log.sample_times().copy(), data[box_start : box_start + 3].T.copy(), data[hand_q].T.copy()


def record_log(execution: ExecutionDiagram, simulator: Simulator, conditions: dict) -> SimLog:
    """Runs `simulator` to the execution's end; what it logged, beside the plan it followed (a replanned
    run's: the plans spliced at each swap) at the same times. When Drake refuses a step (a state beyond
    what its solvers take), what it logged before, with the refusal's message as step_error
    (metrics.detect_divergence: the run diverged)."""
    start = time.perf_counter()
    try:
        execution.executor.advance_to_end(simulator)
    except RuntimeError as e:
        log = collected_log(execution, simulator, conditions, time.perf_counter() - start, complete=False)
        return dataclasses.replace(log, step_error=str(e))
    return collected_log(execution, simulator, conditions, time.perf_counter() - start)


def collected_log(
    execution: ExecutionDiagram,
    simulator: Simulator,
    conditions: dict,
    sim_time_s: float,
    *,
    complete: bool = True,
) -> SimLog:
    """What `simulator` logged so far (to the execution's end, unless not `complete`: a run Drake
    stopped, whose state is not evaluated again), beside the reference followed at the same times."""
    reference = execution.executor.reference_in_effect(simulator.get_context())

    def log_of(logger):
        return finished_log(execution, simulator, logger) if complete else logger.FindLog(simulator.get_context())

    logs = [log_of(logger) for logger in (execution.state_logger, execution.force_logger)]
    t, x, q = split_state_log(execution, logs[0])
    f_W = logs[1].data().T.reshape(len(t), execution.hand_description.num_fingers, 2).copy()
    closed = None
    if execution.closed_loop_loggers is not None:
        data = {name: log_of(logger).data().T.copy() for name, logger in execution.closed_loop_loggers.items()}
        closed = ClosedLoopLog.from_logged(data)
    return SimLog(
        t=t,
        x=x,
        q=q,
        x_plan=reference.object_pose_at(t),
        f_W=f_W,
        f_W_plan=reference.forces_at(t),
        sim_time_s=sim_time_s,
        controller=execution.controller,
        conditions=conditions,
        closed_loop=closed,
    )


def finished_log(execution: ExecutionDiagram, simulator: Simulator, logger):
    """`logger`'s log, with a last sample at the execution's end (the periodic log can miss it by rounding)."""
    log = logger.FindLog(simulator.get_context())
    if log.sample_times()[-1] < execution.end_s(simulator.get_context()) - 1e-9:
        logger.ForcedPublish(logger.GetMyContextFromRoot(simulator.get_context()))
    return log


def simulate_reference(
    reference: Reference,
    config: Config,
    *,
    executor: Executor | None = None,
    meshcat: Meshcat | None = None,
    html_path: str | Path | None = None,
    realtime_rate: float = 0.0,
    conditions: Conditions = NOMINAL,
    plan: PlanResult | None = None,
    segment_workers: int | None = None,
) -> SimResult:
    """Runs the execution Diagram of `executor` (None: config.sim.controller, open loop; grasp-replan
    replans `plan`, the PlanResult of `reference`: execution.replan, its later segments on
    `segment_workers`) for the plan's length plus the settle time (a replanned run's: the plan in effect's
    at the end); the log it records, evaluated by trajectotree.execution.metrics, with the replans."""
    if html_path is not None and meshcat is None:
        meshcat = meshcat_scene.start_meshcat()
    execution = build_execution_diagram(
        reference,
        config,
        executor=executor,
        meshcat=meshcat,
        conditions=conditions,
        plan=plan,
        segment_workers=segment_workers,
    )
    simulator = Simulator(execution.diagram, execution.initial_context(reference))
    simulator.set_target_realtime_rate(realtime_rate)
    if meshcat is not None:
        meshcat_scene.set_planar_view(meshcat)
        meshcat_scene.add_plan_ghost(meshcat, config.scene)
        meshcat.SetTransform(meshcat_scene.PLAN_GHOST_PATH, meshcat_scene.pose_transform(reference.x[0]))
        animation = execution.visualizer.StartRecording()
    log = record_log(execution, simulator, conditions.to_json(config.scene))
    result = metrics.evaluate(log, config.sim.drop_distance, config.scene.gravity, conditions.push_speed(config.scene))
    result = dataclasses.replace(result, replans=execution.executor.replans(simulator.get_context()))
    if meshcat is not None:
        followed = execution.executor.reference_in_effect(simulator.get_context())
        frame_times = np.arange(0.0, execution.end_s(simulator.get_context()) + 1e-9, meshcat_scene.PUBLISH_PERIOD)
        meshcat_scene.animate_plan_ghost(animation, frame_times, followed.object_pose_at(frame_times))
        if html_path is not None:
            playback_page.save_recording_html(
                meshcat,
                execution.visualizer,
                html_path,
                drop_time_s=result.drop_time_s,
                legend=playback_page.simulated_legend(
                    config.scene, arrow_scale(reference), execution.hand_description.num_fingers
                ),
                noun=playback_page.object_noun(config.scene),
                labels=playback_page.finger_labels(execution.plant, execution.hand, execution.hand_description),
            )
        else:
            execution.visualizer.StopRecording()
            execution.visualizer.PublishRecording()
    return result
