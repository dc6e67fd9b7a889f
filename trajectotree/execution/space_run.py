"""Executing a plan in space in a full-dynamics Drake simulation (issue 37), open or closed loop.

The Diagram: a discrete MultibodyPlant (config.sim.time_step, as the plane's) with the hand in space and its cube
on a quaternion floating joint (scene.spatial: the hand's model, add_space_object), gravity along -z, optionally in
a world the plan did not assume (world.Conditions: the friction, the cube's mass, a horizontal push); the executor
(`add_space_executor`: one Executor value dispatched to the space grasp controller, trajectotree.execution.
space_control, open loop or fed by the closed loop's monitors, estimators and push reflex, trajectotree.execution.
closed_loop with its SPACE_OBJECT layout, or zero torque), wired to the plant by port name; loggers of the plant's
state, of each finger's simulated force on the cube and, closed loop, of the estimates. The run starts in the
plan's first state at rest and lasts the plan and config.sim.settle_time of hold; `SpaceSimResult` is what it
logged beside the plan at the same times, with the drop (the cube's centre config.sim.drop_distance off the
plan's, the plane's rule) and the final errors. The controller keeps the plan's values in any world.
Optionally a Meshcat visualizer, as the plane's (trajectotree.execution.simulate): the hand and cube as simulated,
the planned cube's edges, each finger's simulated force on the cube as an arrow, live and into the recording that
becomes the self-contained playback page.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, ContactResults, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem, TriggerType
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from trajectotree.config import Config, ConfigError
from trajectotree.config.executor import Executor, parse_executor
from trajectotree.execution import force_arrows, meshcat_scene, playback_page
from trajectotree.execution.closed_loop import SPACE_OBJECT
from trajectotree.execution.executor import (
    CLOSED_LOOP_OUTPUTS,
    ExecutorSystems,
    add_estimators,
    connect_estimates,
    connect_replanner,
    control_friction,
    export_estimates,
    export_inputs,
)
from trajectotree.execution.in_effect import PLAN_PORT, PlanInEffect, add_plan_source
from trajectotree.execution.space_control import (
    SpaceClosedLoopGraspController,
    SpaceGraspController,
    SpaceReference,
    space_plan_in_effect,
)
from trajectotree.execution.world import NOMINAL, Conditions, PushSource
from trajectotree.figures.legend import arrow_newtons_per_cm
from trajectotree.geometry import quaternion_matrices, rotation_angles
from trajectotree.results import ClosedLoopLog, ReplanEvent
from trajectotree.scene.friction import set_friction
from trajectotree.scene.spatial import SpaceScene, add_space_object

if TYPE_CHECKING:
    from trajectotree.execution.space_replan import SpacePlanning

# the executors a plan in space has
SPACE_EXECUTORS = (Executor.GRASP, Executor.GRASP_CLOSED_LOOP, Executor.GRASP_REPLAN, Executor.NONE)
# rad: the field's two success criteria for a reorientation in space, a run without a drop that ends within 15 deg
# or within 0.4 rad (22.9 deg) of its goal (sim.json within_15deg, within_0p4rad)
SUCCESS_ANGLES = (("within_15deg", math.radians(15.0)), ("within_0p4rad", 0.4))


def space_finger_of_body(plant, hand, scene: SpaceScene) -> dict:
    """{body index in `plant`: finger} of every link of each finger of the hand in space (model instance `hand`
    of `plant`, `scene`'s hand), its fingertip sphere's included."""
    return {
        plant.GetJointByName(joint, hand).child_body().index(): i
        for i, finger in enumerate(scene.hand_file.fingers)
        for joint in finger.joints
    }


def add_space_closed_loop(
    builder, plant, plan: PlanInEffect, config: Config, scene: SpaceScene, planning: SpacePlanning | None = None
) -> None:
    """The SpaceClosedLoopGraspController following `plan` and around it the closed loop's monitors, estimators and
    push reflex for the cube (executor.add_estimators with closed_loop.SPACE_OBJECT), for the caller's `plant`
    holding `scene`'s hand and cube (model instances of the same names, as simulate_space adds them); the inputs
    and outputs add_space_executor names exported. With `planning`, the Replanner (execution.replan, named
    `replanner`) replans it from the measured state and its output is the plan they follow."""
    controller = builder.AddNamedSystem(
        "grasp_controller", SpaceClosedLoopGraspController(scene, config.controller, mu=control_friction(config))
    )
    hand = plant.GetModelInstanceByName(scene.plant.GetModelInstanceName(scene.hand))
    box_body = plant.GetBodyByName("box", plant.GetModelInstanceByName("box")).index()
    loop = add_estimators(
        builder,
        space_finger_of_body(plant, hand, scene),
        box_body,
        scene.num_fingers,
        plant.time_step(),
        config,
        mass=scene.object.mass,
        torque_length=float(np.linalg.norm(scene.object.half)),  # m, the QP's: the cube's half diagonal
        layout=SPACE_OBJECT,
    )
    monitor, motion = loop["monitor"], loop["motion"]
    export_inputs(
        builder,
        {
            "box_state": [controller.box_state_port, monitor.box_state_port, motion.box_state_port],
            "hand_state": [controller.hand_state_port],
            "contact_results": [monitor.contact_results_port],
            "box_contact_forces": [motion.box_contact_forces_port],
        },
    )
    connect_estimates(builder, loop, controller)
    if planning is None:
        plan_output = add_plan_source(builder, plan).get_output_port()
    else:
        from trajectotree.execution.replan import Replanner

        plan_output = connect_replanner(builder, Replanner(planning, plan), loop).plan_port
    for follower in (controller, monitor, loop["friction"]):
        builder.Connect(plan_output, follower.plan_port)
    builder.ExportOutput(controller.actuation_port, "actuation")
    export_estimates(builder, loop)
    builder.ExportOutput(plan_output, PLAN_PORT)


def add_space_executor(
    builder: DiagramBuilder,
    plant,
    reference: SpaceReference,
    config: Config,
    scene: SpaceScene,
    *,
    executor: Executor | str = Executor.GRASP,
    name: str = "executor",
    goal=None,
    segment_workers: int | None = None,
):
    """Adds the executor `executor` of the plan in space `reference` to `builder` as one Diagram named `name`, for
    the caller's finalized `plant` (its actuation in the order of `scene`'s hand, the plan's scene; the hand's and
    the cube's model instances named as in `scene`'s plant). Inputs by name: `box_state` (13: the cube's [qw, qx,
    qy, qz, px, py, pz] and [w_W, v_W], rad/s, m/s), `hand_state` (2 F n: [q rad; v rad/s], finger-major) and,
    closed loop, `contact_results` (the plant's) and `box_contact_forces` (6: the plant's generalized contact
    forces on the cube, [torque N m; force N] in W); outputs: `actuation` (F n joint torques, N m), for grasp and
    grasp-closed-loop `plan` (the PlanInEffect followed) and, closed loop, the estimates and the monitors' outputs
    (executor.CLOSED_LOOP_OUTPUTS: `mu_estimate`, `mass_estimate` kg, `reflex` 0..1, `disturbance` (3, N in W),
    per finger `in_contact`, `slipping`, `force_ratio`, `slip_speed` m/s, and `tracking_error` (6: the rotation
    vector rad and the offset m from the planned pose to the measured one, in W)). The controller assumes the
    plan's scene whatever the plant's. grasp-replan also replans toward the plan's `goal` (unit quaternion
    [w, x, y, z]), a new plan's segments on `segment_workers` local processes (execution.space_replan; its
    Replanner is the subsystem `replanner`: simulate it to ExecutorSystems.end_s, which a replan moves).
    ConfigError for an executor that space does not have yet (SPACE_EXECUTORS) or grasp-replan without a goal."""
    executor = parse_executor(executor)
    inner = DiagramBuilder()
    match executor:
        case Executor.GRASP:
            controller = inner.AddNamedSystem(
                "grasp_controller", SpaceGraspController(scene, config.controller, mu=control_friction(config))
            )
            source = add_plan_source(inner, space_plan_in_effect(reference, config, scene))
            inner.Connect(source.get_output_port(), controller.plan_port)
            inner.ExportInput(controller.box_state_port, "box_state")
            inner.ExportInput(controller.hand_state_port, "hand_state")
            inner.ExportOutput(controller.actuation_port, "actuation")
            inner.ExportOutput(source.get_output_port(), PLAN_PORT)
        case Executor.GRASP_CLOSED_LOOP | Executor.GRASP_REPLAN:
            planning = None
            if executor.replans:
                if goal is None:
                    raise ConfigError("add_space_executor(executor='grasp-replan'): give goal= (the planner's goal)")
                from trajectotree.execution.space_replan import SpacePlanning

                planning = SpacePlanning(tuple(goal), reference, config, scene, segment_workers)
            add_space_closed_loop(inner, plant, space_plan_in_effect(reference, config, scene), config, scene, planning)
        case Executor.NONE:
            zero = inner.AddNamedSystem("zero_torque", ConstantVectorSource(np.zeros(plant.num_actuators())))
            inner.ExportOutput(zero.get_output_port(), "actuation")
        case _:
            raise ConfigError(
                field="executor",
                value=executor.value,
                problem="does not execute plans in space yet",
                choices=tuple(e.value for e in SPACE_EXECUTORS),
            )
    return builder.AddNamedSystem(name, inner.Build())


class SpaceFingertipForces(LeafSystem):
    """Input port `contact_results` (the plant's); output port `f_W` (3F, finger-major): the force of each finger's
    links (fingertip sphere included) on the cube, in W, summed over their point contacts."""

    def __init__(self, plant, hand, box, scene: SpaceScene):
        super().__init__()
        self._num_fingers = scene.num_fingers
        self._finger_of_body = space_finger_of_body(plant, hand, scene)
        self._box_body = plant.GetBodyByName("box", box).index()
        self.contact_results_port = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.DeclareVectorOutputPort("f_W", 3 * self._num_fingers, self.CalcForces)

    def CalcForces(self, context, output):
        results = self.contact_results_port.Eval(context)
        f_W = np.zeros((self._num_fingers, 3))
        for k in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(k)
            a, b = info.bodyA_index(), info.bodyB_index()
            if b == self._box_body and a in self._finger_of_body:
                f_W[self._finger_of_body[a]] += info.contact_force()  # the force on body B, in W
            elif a == self._box_body and b in self._finger_of_body:
                f_W[self._finger_of_body[b]] -= info.contact_force()
        output.SetFromVector(f_W.ravel())


@dataclass(frozen=True)
class SpaceSimResult:
    """A run of a plan in space: what was logged (sim.npz) and its summary (sim.json)."""

    t: np.ndarray  # (T,) s
    x: np.ndarray  # (T, 7) the cube's simulated pose [qw, qx, qy, qz, px, py, pz] in W (plan.npz's layout)
    x_plan: np.ndarray  # (T, 7) the planned pose at the same times
    q: np.ndarray  # (T, F n) rad, the joints, finger-major
    f_W: np.ndarray  # (T, F, 3) N, each finger's simulated force on the cube, in W
    f_W_plan: np.ndarray  # (T, F, 3) N, the planned forces at the same times
    executor: str
    dropped: bool  # the cube's centre went sim.drop_distance off the plan's
    drop_time_s: float | None
    orientation_error_rad: np.ndarray  # (T,) the angle between the simulated and the planned orientation
    position_error_m: np.ndarray  # (T,) the distance between the simulated and the planned centre
    sim_time_s: float  # s of wall time the simulation took
    world: dict  # the simulated world against the plan's (Conditions.world_json: friction, mass kg, push)
    # What the closed loop watched and estimated (sim.npz's CLOSED_LOOP_ARRAYS besides ARRAYS, sim.json's
    # "closed_loop"), as the plane's SimLog; None: an open-loop run
    closed_loop: ClosedLoopLog | None = field(default=None, kw_only=True)
    replans: tuple[ReplanEvent, ...] = field(default=(), kw_only=True)  # grasp-replan: each time it planned again

    ARRAYS = ("t", "x", "x_plan", "q", "f_W", "f_W_plan")

    @property
    def controller(self) -> str:
        """The controller that ran (the plane's name: figures.legend.controller_text)."""
        return Executor(self.executor).controller

    @property
    def conditions(self) -> dict:
        """The simulated world against the plan's, as the plane's SimLog's (figures.run.world_text)."""
        return self.world

    def to_json(self) -> dict:
        """sim.json: the drop, the errors at the end (against the plan's end, its goal where it succeeded) and
        the largest on the way, and whether the run meets each of SUCCESS_ANGLES (a dropped run meets neither)."""
        final = float(self.orientation_error_rad[-1])
        return {
            "kind": "space",
            "executor": self.executor,
            "dropped": self.dropped,
            "drop_time_s": self.drop_time_s,
            "duration_s": float(self.t[-1]),
            "final_orientation_error_rad": final,
            "final_orientation_error_deg": float(np.degrees(final)),
            **{name: not self.dropped and final <= angle for name, angle in SUCCESS_ANGLES},
            "final_position_error_m": float(self.position_error_m[-1]),
            "max_orientation_error_rad": float(self.orientation_error_rad.max()),
            "max_position_error_m": float(self.position_error_m.max()),
            "sim_time_s": self.sim_time_s,
            "conditions": self.world,
            **({} if self.closed_loop is None else {"closed_loop": self.closed_loop.to_json(self.t)}),
            **({"replans": [e.to_json() for e in self.replans]} if Executor(self.executor).replans else {}),
        }


def pose_errors(x, x_plan) -> tuple[np.ndarray, np.ndarray]:
    """(angle rad (T,), distance m (T,)) between the poses x and x_plan (T, 7)."""
    R, R_plan = quaternion_matrices(x[:, :4]), quaternion_matrices(x_plan[:, :4])
    angle = rotation_angles(np.swapaxes(R_plan, -1, -2) @ R)
    return angle, np.linalg.norm(x[:, 4:] - x_plan[:, 4:], axis=1)


def simulate_space(
    reference: SpaceReference,
    config: Config,
    scene: SpaceScene,
    *,
    executor: Executor | str = Executor.GRASP,
    conditions: Conditions = NOMINAL,
    meshcat: Meshcat | None = None,
    html_path=None,
    goal=None,
    segment_workers: int | None = None,
) -> SpaceSimResult:
    """Runs the plan in space `reference` (the plan of `scene`: its hand, cube and friction, and the controller's
    model) with `executor` for its length and config.sim.settle_time in the simulated world `conditions` (the
    plant's friction between the fingers and the cube, the cube's mass, a push on its centre); the log beside the
    plan. With `meshcat` (live: the run in real time) or `html_path` (the recording, as a self-contained page),
    the run drawn in Meshcat. grasp-replan replans toward `goal` (add_space_executor) and runs to the end of the
    plan in effect; the log's planned values are those of the plans followed, the result lists the replans."""
    executor = parse_executor(executor)
    live = meshcat is not None
    if html_path is not None and meshcat is None:
        meshcat = meshcat_scene.start_meshcat()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    (hand,) = Parser(plant).AddModels(scene.hand_file.model)
    simulated = conditions.simulated_object(scene.object)
    box = add_space_object(plant, simulated)
    # Drake combines the two sides' coefficients of a contact (2 a b / (a + b)): the hand's the cube's, so that the
    # fingers touch the cube with `simulated.mu` whatever the hand's model file says (0.7 for fingerpro4).
    set_friction(plant, scene_graph, hand, simulated.mu)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -scene.gravity])
    plant.Finalize()
    added = add_space_executor(
        builder, plant, reference, config, scene, executor=executor, goal=goal, segment_workers=segment_workers
    )
    plant_ports = {
        "box_state": plant.get_state_output_port(box),
        "hand_state": plant.get_state_output_port(hand),
        "contact_results": plant.get_contact_results_output_port(),
        "box_contact_forces": plant.get_generalized_contact_forces_output_port(box),
    }
    for i in range(added.num_input_ports()):  # by name, as executor.connect_executor
        builder.Connect(plant_ports[added.get_input_port(i).get_name()], added.get_input_port(i))
    builder.Connect(added.GetOutputPort("actuation"), plant.get_actuation_input_port())
    if conditions.push is not None:
        pusher = builder.AddNamedSystem("push", PushSource(plant, box, conditions.push))
        builder.Connect(pusher.spatial_forces_port, plant.get_applied_spatial_force_input_port())
    forces = builder.AddNamedSystem("fingertip_forces", SpaceFingertipForces(plant, hand, box, scene))
    builder.Connect(plant.get_contact_results_output_port(), forces.contact_results_port)
    triggers = {TriggerType.kPeriodic, TriggerType.kForced}
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, triggers, config.sim.log_period)
    force_logger = LogVectorOutput(forces.get_output_port(), builder, triggers, config.sim.log_period)
    closed_loop_loggers = {}
    if executor.closed_loop:
        closed_loop_loggers = {
            name: LogVectorOutput(added.GetOutputPort(name), builder, triggers, config.sim.log_period)
            for name in CLOSED_LOOP_OUTPUTS
        }
    visualizer = None
    if meshcat is not None:
        visualizer = meshcat_scene.add_space_visualizer(
            builder, plant, scene_graph, hand, box, scene.hand_file, meshcat
        )
        force_arrows.add_space_force_arrows_system(
            builder, plant, hand, scene, meshcat, forces.get_output_port(), space_arrow_scale(reference)
        )
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, box, reference.x[0])
    plant.SetPositions(plant_context, hand, reference.q[0])
    simulator = Simulator(diagram, context)
    replanner = added.GetSubsystemByName("replanner") if executor.replans else None
    systems = ExecutorSystems(added, executor, reference, config.sim.settle_time, replanner)
    if visualizer is not None:
        simulator.set_target_realtime_rate(1.0 if live else 0.0)  # a live view at the run's pace, as the plane's
        meshcat_scene.add_space_plan_ghost(meshcat, scene.object.size)
        meshcat.SetTransform(meshcat_scene.PLAN_GHOST_PATH, meshcat_scene.pose_transform(reference.x[0]))
        animation = visualizer.StartRecording()
    start = time.perf_counter()
    systems.advance_to_end(simulator)
    sim_time = time.perf_counter() - start
    end = systems.end_s(simulator.get_context())
    followed = systems.reference_in_effect(simulator.get_context())
    loggers = [state_logger, force_logger, *closed_loop_loggers.values()]
    logs = [logger.FindLog(simulator.get_context()) for logger in loggers]
    if logs[0].sample_times()[-1] < end - 1e-9:  # the periodic log can miss the end by rounding
        for logger in loggers:
            logger.ForcedPublish(logger.GetMyContextFromRoot(simulator.get_context()))
    t, states = logs[0].sample_times().copy(), logs[0].data().T
    x = states[:, plant.GetPositionsFromArray(box, np.arange(plant.num_positions())).astype(int)]
    q = states[:, plant.GetPositionsFromArray(hand, np.arange(plant.num_positions())).astype(int)]
    x_plan = followed.pose_at(t)
    angle, distance = pose_errors(x, x_plan)
    off = np.flatnonzero(distance > config.sim.drop_distance)
    result = SpaceSimResult(
        t=t,
        x=x,
        x_plan=x_plan,
        q=q,
        f_W=logs[1].data().T.reshape(len(t), scene.num_fingers, 3).copy(),
        f_W_plan=followed.forces_at(t),
        executor=executor.value,
        dropped=len(off) > 0,
        drop_time_s=float(t[off[0]]) if len(off) else None,
        orientation_error_rad=angle,
        position_error_m=distance,
        sim_time_s=sim_time,
        world=conditions.world_json(scene.object.mu, scene.object.mass),
        closed_loop=ClosedLoopLog.from_logged(
            {name: log.data().T.copy() for name, log in zip(closed_loop_loggers, logs[2:])}
        )
        if closed_loop_loggers
        else None,
        replans=systems.replans(simulator.get_context()),
    )
    if visualizer is not None:
        frame_times = np.arange(0.0, end + 1e-9, meshcat_scene.PUBLISH_PERIOD)
        meshcat_scene.animate_plan_ghost(animation, frame_times, followed.pose_at(frame_times))
        save_space_recording(meshcat, visualizer, html_path, result, reference, scene)
    return result


def space_arrow_scale(reference: SpaceReference) -> float:
    """The force arrows' scale (N per cm) of a run of `reference`: the plan's, as the plane's simulate.arrow_scale,
    so that the run's playback, the plan's and the GIF share it."""
    return arrow_newtons_per_cm(reference.f_W)


def save_space_recording(meshcat, visualizer, html_path, result: SpaceSimResult, reference, scene) -> None:
    """The run's recording published to `meshcat` and, at `html_path` (None: not written), its playback page:
    titled as the plane's, the drop marked, a legend that says the arrows are the simulated forces."""
    if html_path is None:
        visualizer.StopRecording()
        visualizer.PublishRecording()
        return
    playback_page.save_recording_html(
        meshcat,
        visualizer,
        html_path,
        drop_time_s=result.drop_time_s,
        legend=playback_page.run_legend(
            "cube", "edges", space_arrow_scale(reference), scene.num_fingers, links=playback_page.LEGEND_SPACE_LINKS
        ),
        noun="cube",
        labels=playback_page.space_finger_labels(scene),
    )
