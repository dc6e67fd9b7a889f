"""Executing a plan in a full-dynamics Drake simulation (paper Sec. III-D, IV-D).

The execution Diagram: a discrete MultibodyPlant with the hand and box from
models/ (point contact between fingertip spheres, links and the box, friction
from the config, gravity -y), reference sources from the plan (fingertip
positions, velocities and forces, held at their last value for
SimConfig.settle_time after the plan ends), a controller (the object-level
GraspController, default, or eq. 20's ImpedanceController, `controller="paper"`),
loggers of the plant state and of each finger's simulated force on the box
(`FingertipForces`) and, optionally, a Meshcat visualizer. A run records a
`SimLog` (the logs beside the plan at the same times), which
`trajectotree.execution.metrics.evaluate` turns into the `SimResult` the functions here return.

`Conditions` change the simulated world only, never what the controller assumes:
the friction coefficient (sim_mu), the box mass (sim_mass: model mismatch) and a
push, a force on the box in W for SimConfig.push_duration seconds.

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
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    ContactResults,
    ExternallyAppliedSpatialForce,
    MultibodyPlantConfig,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem, TriggerType
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from trajectotree.config import Config, ConfigError, check_controller, check_length, check_range
from trajectotree.execution import closed_loop, metrics, playback
from trajectotree.execution.control import GraspController, ImpedanceController
from trajectotree.execution.reference import GraspSchedule, Reference, grasp_schedule
from trajectotree.figures.run import arrow_newtons_per_cm
from trajectotree.results import ClosedLoopLog, SimLog, SimResult
from trajectotree.scene.hand import HandDescription, finger_bodies, hand_file, read_hand
from trajectotree.scene.plant import Scene, add_hand_and_box, build_scene


@dataclass(frozen=True)
class Push:
    """A force on the box's centre, in W, from time_s for duration_s."""

    force: tuple[float, float]  # N, (f_x, f_y) in W
    time_s: float  # s, when it starts
    duration_s: float = 0.2  # s, how long it acts

    def __post_init__(self):
        check_length("push force", self.force, 2, "f_x N, f_y N")
        for i, f in enumerate(self.force):
            check_range("push force", f, -100.0, 100.0, index=(i,))
        check_range("push time", self.time_s, 0.0, None)
        check_range("push duration", self.duration_s, 0.0, 10.0, low_open=True)


def parse_push(text: str, duration_s: float = 0.2) -> Push:
    """A Push from "FX,FY@T" (N, N, s), e.g. "0.2,0@3.5"; ConfigError naming the text."""
    try:
        force, at = str(text).split("@")
        fx, fy = (float(v) for v in force.split(","))
        start = float(at)
    except ValueError:
        raise ConfigError(f"push {text!r} is not FX,FY@T (force in N in W, start time in s, e.g. 0.2,0@3.5)") from None
    try:
        return Push(force=(fx, fy), time_s=start, duration_s=duration_s)
    except ConfigError as e:
        raise ConfigError(f"push {text!r}: {e}") from None


@dataclass(frozen=True)
class Conditions:
    """The simulated world where it differs from the plan's; the controller keeps the plan's values."""

    mu: float | None = None  # friction coefficient of the simulated plant (None: the scene's)
    mass: float | None = None  # kg, box mass of the simulated plant (None: the scene's)
    push: Push | None = None  # a push on the box, or none

    def __post_init__(self):
        if self.mu is not None:
            check_range("sim_mu", self.mu, 0.0, 5.0, low_open=True)
        if self.mass is not None:
            check_range("sim_mass", self.mass, 0.0, 100.0, low_open=True)

    def scene(self, scene_config):
        """The simulated plant's SceneConfig."""
        changes = {k: v for k, v in (("mu", self.mu), ("box_mass", self.mass)) if v is not None}
        if self.mass is not None and scene_config.object_inertia is not None:  # the same body, heavier
            changes["object_inertia"] = scene_config.inertia_zz(self.mass)
        return dataclasses.replace(scene_config, **changes)

    def to_json(self, scene_config) -> dict:
        sim = self.scene(scene_config)
        push = (
            None
            if self.push is None
            else {"force": list(self.push.force), "time_s": self.push.time_s, "duration_s": self.push.duration_s}
        )
        return {
            "sim_mu": sim.mu,
            "sim_mass": sim.box_mass,
            "plan_mu": scene_config.mu,
            "plan_mass": scene_config.box_mass,
            "push": push,
        }


class PushSource(LeafSystem):
    """Output port `spatial_forces` (list of ExternallyAppliedSpatialForce, for the
    plant's applied-spatial-force input): the push on the box while it acts, else none."""

    def __init__(self, plant, box, push: Push):
        super().__init__()
        self._body = plant.GetBodyByName("box", box).index()
        self._push = push
        self.spatial_forces_port = self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self.CalcForces
        )

    def CalcForces(self, context, output):
        push, t = self._push, context.get_time()
        forces = []
        if push.time_s <= t < push.time_s + push.duration_s:
            applied = ExternallyAppliedSpatialForce()
            applied.body_index = self._body
            applied.p_BoBq_B = np.zeros(3)  # at the box origin, its centre of mass
            applied.F_Bq_W = SpatialForce(np.zeros(3), np.array([push.force[0], push.force[1], 0.0]))
            forces.append(applied)
        output.set_value(forces)


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
    duration: float  # s, plan length + settle time
    controller: str  # "grasp", "paper" or "none" (uncontrolled)
    # closed loop: {ClosedLoopLog field: VectorLogSink of the output port of that name}; open loop: None
    closed_loop_loggers: dict | None = None

    def initial_context(self, reference: Reference):
        """A context in the plan's first state: object pose x_0, joint angles q_0, at rest."""
        context = self.diagram.CreateDefaultContext()
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        self.plant.SetPositions(plant_context, self.box, reference.x[0])
        self.plant.SetPositions(plant_context, self.hand, reference.q[0])
        return context


def held_trajectory(times, values, hold: float) -> PiecewisePolynomial:
    """First-order hold through (times, values (K, n)), then constant for `hold` seconds."""
    if hold > 0:
        times = np.append(times, times[-1] + hold)
        values = np.vstack([values, values[-1]])
    return PiecewisePolynomial.FirstOrderHold(times, np.asarray(values).T)


def add_paper_controller(builder, plant, hand, reference: Reference, config: Config) -> ImpedanceController:
    """Eq. 20 fed by reference sources (fingertip positions, velocities, forces)."""
    controller = builder.AddNamedSystem("impedance_controller", ImpedanceController(config.scene, config.controller))

    def flat(a):
        return a.reshape(len(reference.t), -1)  # (K, F, 2) -> (K, 2F), finger-major

    hold = config.sim.settle_time
    for name, values in (("p_WF_ref", reference.p_WF), ("v_WF_ref", reference.v_WF), ("f_W_ref", reference.f_W)):
        source = builder.AddNamedSystem(name, TrajectorySource(held_trajectory(reference.t, flat(values), hold)))
        builder.Connect(source.get_output_port(), controller.GetInputPort(name))
    builder.Connect(plant.get_state_output_port(hand), controller.hand_state_port)
    return controller


def execution_schedule(reference: Reference, config: Config, scene: Scene) -> GraspSchedule:
    """The grasp controller's schedule of `reference`, sampled at its rate, to the run's end
    (the plan, then config.sim.settle_time of hold)."""
    gains = config.controller
    return grasp_schedule(
        reference,
        shape=config.scene.shape,
        tip_radius=scene.tip_radius,
        period=1.0 / gains.rate_hz,
        duration=reference.duration + config.sim.settle_time,
        ramp_time=gains.ramp_time,
        swing_lift=gains.swing_lift,
        contact_distance=gains.contact_distance,
    )


def add_grasp_controller(
    builder, plant, hand, box, reference: Reference, config: Config, closed_loop: bool = False, plan_mu=None
) -> GraspController:
    """The GraspController with the plan's scene (mass, size) and friction cones at
    max(search.friction_safety, controller.friction_safety) x scene.mu (never less friction than
    the plan assumed), reading the box and hand state; with closed_loop, its estimate and
    reflex ports are left for add_closed_loop to connect. plan_mu: the friction the plan in
    effect assumes, where its landing reflex compares the estimate (None: scene.mu)."""
    scene, gains = build_scene(config.scene), config.controller
    schedule = execution_schedule(reference, config, scene)
    mu_control = max(config.search.friction_safety, gains.friction_safety) * config.scene.mu
    controller = builder.AddNamedSystem(
        "grasp_controller",
        GraspController(scene, schedule, gains, mu=mu_control, closed_loop=closed_loop, plan_mu=plan_mu),
    )
    builder.Connect(plant.get_state_output_port(box), controller.box_state_port)
    builder.Connect(plant.get_state_output_port(hand), controller.hand_state_port)
    return controller


def add_closed_loop(
    builder, plant, hand, box, description: HandDescription, controller: GraspController, config: Config
) -> dict:
    """The contact and object monitors, the friction and mass estimators and the push reflex
    (trajectotree.execution.closed_loop), wired to the plant and into `controller`'s estimate
    ports; returns {output name: output port} of every quantity a ClosedLoopLog records."""
    gains, scene = config.controller, config.scene
    monitor = builder.AddNamedSystem(
        "contact_monitor", closed_loop.ContactMonitor(plant, hand, box, description, controller.schedule, gains)
    )
    builder.Connect(plant.get_contact_results_output_port(), monitor.contact_results_port)
    builder.Connect(plant.get_state_output_port(box), monitor.box_state_port)
    motion = builder.AddNamedSystem("object_monitor", closed_loop.ObjectMonitor(plant.time_step()))
    builder.Connect(plant.get_state_output_port(box), motion.box_state_port)
    builder.Connect(plant.get_generalized_contact_forces_output_port(box), motion.box_contact_forces_port)
    friction = builder.AddNamedSystem(
        "friction_estimator",
        closed_loop.FrictionEstimator(scene.mu, scene.shape.circumradius, controller.schedule, gains),
    )
    mass = builder.AddNamedSystem("mass_estimator", closed_loop.MassEstimator(scene.box_mass, scene.gravity, gains))
    reflex = builder.AddNamedSystem("push_reflex", closed_loop.PushReflex(scene.gravity, gains))
    for source, target, name in (
        (monitor, friction, "slipping"),
        (monitor, friction, "force_ratio"),
        (monitor, friction, "normal_force"),
        (monitor, friction, "approach_speed"),
        (reflex, friction, "reflex"),
        (monitor, friction, "tracking_error"),
        (motion, mass, "contact_force"),
        (motion, mass, "acceleration"),
        (motion, reflex, "acceleration"),
        (motion, reflex, "contact_force"),
        (mass, reflex, "mass_estimate"),
        (friction, controller, "mu_estimate"),
        (mass, controller, "mass_estimate"),
        (reflex, controller, "reflex"),
        (reflex, controller, "disturbance"),
    ):
        builder.Connect(source.GetOutputPort(name), target.GetInputPort(name))
    logged = {name: monitor.GetOutputPort(name) for name in ClosedLoopLog.MONITOR_ARRAYS}
    logged |= {
        "mu_estimate": friction.GetOutputPort("mu_estimate"),
        "mass_estimate": mass.GetOutputPort("mass_estimate"),
    }
    return logged | {name: reflex.GetOutputPort(name) for name in ("disturbance", "reflex")}


def build_execution_diagram(
    reference: Reference,
    config: Config,
    *,
    meshcat: Meshcat | None = None,
    controlled: bool = True,
    controller: str | None = None,
    conditions: Conditions = Conditions(),
    closed_loop: bool = False,
    plan_mu: float | None = None,
) -> ExecutionDiagram:
    """The Diagram that executes `reference` with `controller` (default
    config.sim.controller) in the world `conditions` describe; controlled=False applies
    zero torque (the open-loop hand, for checking that the controller holds the box).
    closed_loop adds the contact monitor, the estimators and the push reflex around the
    grasp controller (add_closed_loop) and their loggers. plan_mu: the friction the plan in
    effect assumes (None: config.scene.mu; a replanned phase's plan assumed the estimate)."""
    kind = check_closed_loop(check_controller(controller or config.sim.controller), closed_loop and controlled)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    hand, box = add_hand_and_box(plant, conditions.scene(config.scene), scene_graph)
    plant.Finalize()
    description = read_hand(plant, scene_graph, hand, hand_file(config.scene.hand))
    hold = config.sim.settle_time
    if not controlled:
        system = builder.AddNamedSystem("zero_torque", ConstantVectorSource(np.zeros(plant.num_actuators())))
        actuation = system.get_output_port()
    elif kind == "paper":
        actuation = add_paper_controller(builder, plant, hand, reference, config).actuation_port
    else:
        grasp = add_grasp_controller(
            builder, plant, hand, box, reference, config, closed_loop=closed_loop, plan_mu=plan_mu
        )
        actuation = grasp.actuation_port
    builder.Connect(actuation, plant.get_actuation_input_port())
    if conditions.push is not None:
        push = builder.AddNamedSystem("push", PushSource(plant, box, conditions.push))
        builder.Connect(push.spatial_forces_port, plant.get_applied_spatial_force_input_port())
    triggers = {TriggerType.kPeriodic, TriggerType.kForced}
    state_logger = LogVectorOutput(plant.get_state_output_port(), builder, triggers, config.sim.log_period)
    forces = builder.AddNamedSystem("fingertip_forces", FingertipForces(plant, hand, box, description))
    builder.Connect(plant.get_contact_results_output_port(), forces.contact_results_port)
    force_logger = LogVectorOutput(forces.get_output_port(), builder, triggers, config.sim.log_period)
    closed_loop_loggers = None
    if closed_loop and controlled:
        ports = add_closed_loop(builder, plant, hand, box, description, grasp, config)
        closed_loop_loggers = {
            name: LogVectorOutput(port, builder, triggers, config.sim.log_period) for name, port in ports.items()
        }
    visualizer = None
    if meshcat is not None:
        visualizer = playback.add_visualizer(builder, plant, scene_graph, hand, description, meshcat)
        playback.add_force_arrows_system(
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
        duration=reference.duration + hold,
        controller=kind if controlled else "none",
        closed_loop_loggers=closed_loop_loggers,
    )


def arrow_scale(reference: Reference) -> float:
    """The force arrows' scale (N per cm) of a run of `reference`: set by the plan's forces, so that
    the playback and the GIF of one plan share it and a dropped box's squeeze does not shrink it."""
    return arrow_newtons_per_cm(reference.f_W)


def check_closed_loop(controller: str, closed_loop: bool) -> str:
    """`controller`, unless the closed loop is asked for around another than the grasp controller."""
    if closed_loop and controller != "grasp":
        raise ConfigError(
            field="controller",
            value=controller,
            problem=": the closed loop runs around the grasp controller only",
            choices=("grasp",),
        )
    return controller


def split_state_log(execution: ExecutionDiagram, log) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (T,), object pose (T, 3), joint angles (T, 2F), finger-major) from the plant-state log."""
    plant = execution.plant
    box_start = plant.GetJointByName("box_planar").position_start()
    hand_q = [
        plant.GetJointByName(name, execution.hand).position_start() for name in execution.hand_description.joint_names
    ]
    data = log.data()
    return log.sample_times().copy(), data[box_start : box_start + 3].T.copy(), data[hand_q].T.copy()


def record_log(execution: ExecutionDiagram, simulator: Simulator, reference: Reference, conditions: dict) -> SimLog:
    """Runs `simulator` to the execution's end; what it logged, beside the plan at the same times."""
    start = time.perf_counter()
    simulator.AdvanceTo(execution.duration)
    return collected_log(execution, simulator, reference, conditions, time.perf_counter() - start)


def collected_log(
    execution: ExecutionDiagram, simulator: Simulator, reference: Reference, conditions: dict, sim_time_s: float
) -> SimLog:
    """What `simulator` logged so far (to the execution's end), beside `reference` at the same times."""
    logs = [finished_log(execution, simulator, logger) for logger in (execution.state_logger, execution.force_logger)]
    t, x, q = split_state_log(execution, logs[0])
    f_W = logs[1].data().T.reshape(len(t), execution.hand_description.num_fingers, 2).copy()
    closed = None
    if execution.closed_loop_loggers is not None:
        data = {
            name: finished_log(execution, simulator, logger).data().T.copy()
            for name, logger in execution.closed_loop_loggers.items()
        }
        for name in ("in_contact", "slipping"):
            data[name] = data[name] > 0.5
        for name in ("mu_estimate", "mass_estimate", "reflex"):
            data[name] = data[name][:, 0]
        closed = ClosedLoopLog(**data)
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
    if log.sample_times()[-1] < execution.duration - 1e-9:
        logger.ForcedPublish(logger.GetMyContextFromRoot(simulator.get_context()))
    return log


def simulate_reference(
    reference: Reference,
    config: Config,
    *,
    meshcat: Meshcat | None = None,
    html_path: str | Path | None = None,
    controlled: bool = True,
    realtime_rate: float = 0.0,
    controller: str | None = None,
    conditions: Conditions = Conditions(),
    closed_loop: bool = False,
) -> SimResult:
    """Runs the execution Diagram for the plan's length plus the settle time; the log it
    records, evaluated by trajectotree.execution.metrics."""
    if html_path is not None and meshcat is None:
        meshcat = playback.start_meshcat()
    execution = build_execution_diagram(
        reference,
        config,
        meshcat=meshcat,
        controlled=controlled,
        controller=controller,
        conditions=conditions,
        closed_loop=closed_loop,
    )
    simulator = Simulator(execution.diagram, execution.initial_context(reference))
    simulator.set_target_realtime_rate(realtime_rate)
    if meshcat is not None:
        playback.set_planar_view(meshcat)
        playback.add_plan_ghost(meshcat, config.scene)
        meshcat.SetTransform(playback.PLAN_GHOST_PATH, playback.pose_transform(reference.x[0]))
        animation = execution.visualizer.StartRecording()
    log = record_log(execution, simulator, reference, conditions.to_json(config.scene))
    result = metrics.evaluate(log, config.sim.drop_distance)
    if meshcat is not None:
        frame_times = np.arange(0.0, execution.duration + 1e-9, playback.PUBLISH_PERIOD)
        playback.animate_plan_ghost(animation, frame_times, reference.object_pose_at(frame_times))
        if html_path is not None:
            playback.save_recording_html(
                meshcat,
                execution.visualizer,
                html_path,
                drop_time_s=result.drop_time_s,
                legend=playback.simulated_legend(
                    config.scene, arrow_scale(reference), execution.hand_description.num_fingers
                ),
                noun=playback.object_noun(config.scene),
                labels=playback.finger_labels(execution.plant, execution.hand, execution.hand_description),
            )
        else:
            execution.visualizer.StopRecording()
            execution.visualizer.PublishRecording()
    return result
