"""An executor as a Diagram that a caller adds to their own DiagramBuilder and wires by port name, as
Drake's MakeHardwareStation users wire their controllers: `add_executor` adds the controller of one
`config.executor.Executor` (and, for a closed-loop one, the contact and object monitors, the estimators
and the reflexes around it: trajectotree.execution.closed_loop, .reflexes) for the caller's plant.

Its ports (F fingers; units m, rad, s, N, N m):
- input `box_state` (6): the object's planar joint [x m, y m, theta rad, xdot m/s, ydot m/s, thetadot rad/s];
- input `hand_state` (4F): the hand's [q rad; v rad/s], finger-major (each finger's joints from its base out);
- closed loop: input `contact_results` (the plant's ContactResults, abstract) and `box_contact_forces` (3: the
  plant's generalized contact forces on the object, f_x N, f_y N in W, torque N m);
- output `actuation` (2F): the joint torques, N m, in the plant's actuation input order;
- closed loop: outputs `mu_estimate` (1), `mass_estimate` (1, kg), `reflex` (1, 0..1), `disturbance` (2, N in W)
  and the contact monitor's per finger (F each) `in_contact` (1/0), `slipping` (1/0), `force_ratio` (1),
  `slip_speed` (m/s) and the object's `tracking_error` (3: measured - planned pose, m, m, rad).
The replanning executor runs its closed loop here; its replanner is trajectotree.execution.replan, outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from trajectotree.config import Config, ConfigError
from trajectotree.config.executor import Executor, parse_executor
from trajectotree.execution import closed_loop
from trajectotree.execution.control import ClosedLoopGraspController, GraspController
from trajectotree.execution.impedance import ImpedanceController
from trajectotree.execution.reference import GraspSchedule, Reference, grasp_schedule, reference_from_plan
from trajectotree.execution.reflexes import ConeFriction, LandingReflex
from trajectotree.results import ClosedLoopLog, PlanResult
from trajectotree.scene.hand import HandDescription, hand_file, read_hand
from trajectotree.scene.plant import Scene, build_scene

# The closed loop's outputs besides the actuation: what a ClosedLoopLog records.
CLOSED_LOOP_OUTPUTS = ClosedLoopLog.MONITOR_ARRAYS + ("mu_estimate", "mass_estimate", "disturbance", "reflex")


def held_trajectory(times, values, hold: float) -> PiecewisePolynomial:
    """First-order hold through (times, values (K, n)), then constant for `hold` seconds."""
    if hold > 0:
        times = np.append(times, times[-1] + hold)
        values = np.vstack([values, values[-1]])
    return PiecewisePolynomial.FirstOrderHold(times, np.asarray(values).T)


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
        ramp_time=gains.grasp.ramp_time,
        swing_lift=gains.grasp.swing_lift,
        contact_distance=gains.grasp.contact_distance,
    )


def control_friction(config: Config) -> float:
    """The friction the grasp controller's cones allow: max(search.friction_safety,
    controller.grasp.friction_safety) x scene.mu (never less friction than the plan assumed)."""
    return max(config.search.friction_safety, config.controller.grasp.friction_safety) * config.scene.mu


@dataclass(frozen=True)
class ExecutorSystems:
    """What add_executor added: `diagram`, the executor as one system of the caller's Diagram, with the
    ports the module doc names; the `executor` it runs; its `landing_reflex` (closed loop: a replanned
    phase restarts it, else None); `duration`, s, the plan's length and config.sim.settle_time of hold."""

    diagram: Diagram
    executor: Executor
    landing_reflex: LandingReflex | None
    duration: float

    def GetInputPort(self, name: str):
        return self.diagram.GetInputPort(name)

    def GetOutputPort(self, name: str):
        return self.diagram.GetOutputPort(name)


def add_paper_controller(builder, reference: Reference, config: Config) -> None:
    """Eq. 20 fed by reference sources (fingertip positions, velocities, forces)."""
    controller = builder.AddNamedSystem("impedance_controller", ImpedanceController(config.scene, config.controller))

    def flat(a):
        return a.reshape(len(reference.t), -1)  # (K, F, 2) -> (K, 2F), finger-major

    hold = config.sim.settle_time
    for name, values in (("p_WF_ref", reference.p_WF), ("v_WF_ref", reference.v_WF), ("f_W_ref", reference.f_W)):
        source = builder.AddNamedSystem(name, TrajectorySource(held_trajectory(reference.t, flat(values), hold)))
        builder.Connect(source.get_output_port(), controller.GetInputPort(name))
    builder.ExportInput(controller.hand_state_port, "hand_state")
    builder.ExportOutput(controller.actuation_port, "actuation")


def add_grasp_controller(builder, scene: Scene, schedule: GraspSchedule, config: Config) -> None:
    """The open-loop GraspController with the plan's scene (mass, size) and friction (control_friction)."""
    controller = builder.AddNamedSystem(
        "grasp_controller", GraspController(scene, schedule, config.controller, mu=control_friction(config))
    )
    builder.ExportInput(controller.box_state_port, "box_state")
    builder.ExportInput(controller.hand_state_port, "hand_state")
    builder.ExportOutput(controller.actuation_port, "actuation")


def add_closed_loop_grasp(
    builder, plant, hand, box, description: HandDescription, scene: Scene, schedule, config: Config, mu_assumed: float
) -> LandingReflex:
    """The ClosedLoopGraspController and around it the contact and object monitors, the friction and
    mass estimators, the push reflex (trajectotree.execution.closed_loop), the landing reflex and the
    cones' friction (trajectotree.execution.reflexes), wired to each other and to the exported inputs.
    mu_assumed: the friction the plan in effect assumes, where the landing reflex compares the estimate
    and the cones start. Returns the landing reflex."""
    gains, scene_config = config.controller, config.scene
    controller = builder.AddNamedSystem(
        "grasp_controller", ClosedLoopGraspController(scene, schedule, gains, mu=control_friction(config))
    )
    landing = builder.AddNamedSystem("landing_reflex", LandingReflex(scene, schedule, gains, mu_assumed=mu_assumed))
    cones = builder.AddNamedSystem("cone_friction", ConeFriction(gains, mu_assumed=mu_assumed))
    monitor = builder.AddNamedSystem(
        "contact_monitor", closed_loop.ContactMonitor(plant, hand, box, description, schedule, gains)
    )
    motion = builder.AddNamedSystem("object_monitor", closed_loop.ObjectMonitor(plant.time_step()))
    friction = builder.AddNamedSystem(
        "friction_estimator",
        closed_loop.FrictionEstimator(scene_config.mu, scene_config.shape.circumradius, schedule, gains),
    )
    mass = builder.AddNamedSystem(
        "mass_estimator", closed_loop.MassEstimator(scene_config.box_mass, scene_config.gravity, gains)
    )
    reflex = builder.AddNamedSystem("push_reflex", closed_loop.PushReflex(scene_config.gravity, gains))
    box_state = [controller.box_state_port, landing.box_state_port, monitor.box_state_port, motion.box_state_port]
    for name, ports in (
        ("box_state", box_state),
        ("hand_state", [controller.hand_state_port, landing.hand_state_port]),
        ("contact_results", [monitor.contact_results_port]),
        ("box_contact_forces", [motion.box_contact_forces_port]),
    ):
        index = builder.ExportInput(ports[0], name)
        for port in ports[1:]:
            builder.ConnectInput(index, port)
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
        (friction, cones, "mu_estimate"),
        (friction, landing, "mu_estimate"),
        (reflex, landing, "reflex"),
        (cones, controller, "friction"),
        (landing, controller, "clocks"),
        (mass, controller, "mass_estimate"),
        (reflex, controller, "reflex"),
        (reflex, controller, "disturbance"),
    ):
        builder.Connect(source.GetOutputPort(name), target.GetInputPort(name))
    builder.ExportOutput(controller.actuation_port, "actuation")
    for name in ClosedLoopLog.MONITOR_ARRAYS:
        builder.ExportOutput(monitor.GetOutputPort(name), name)
    builder.ExportOutput(friction.GetOutputPort("mu_estimate"), "mu_estimate")
    builder.ExportOutput(mass.GetOutputPort("mass_estimate"), "mass_estimate")
    for name in ("disturbance", "reflex"):
        builder.ExportOutput(reflex.GetOutputPort(name), name)
    return landing


def add_executor(
    builder: DiagramBuilder,
    plant,
    plan: PlanResult | Reference,
    config: Config | None = None,
    *,
    scene_graph,
    hand,
    box,
    executor: Executor | str = Executor.GRASP_CLOSED_LOOP,
    mu_assumed: float | None = None,
    name: str = "executor",
) -> ExecutorSystems:
    """Adds the executor `executor` (an Executor or its name) of `plan` (a PlanResult, or a Reference
    with `config`) to `builder` as one Diagram named `name`, for the caller's finalized `plant` (with
    its `scene_graph` and the `hand` and `box` model instances, as scene.plant.add_hand_and_box adds them
    to a plant of the plan's scene): its ports (module doc) are left for the caller to connect by name.
    The controller assumes the plan's scene (`config.scene`: its friction and mass), whatever the plant's.
    mu_assumed: the friction the plan in effect assumes (None: config.scene.mu). The zero-torque executor
    has only its `actuation` output. ConfigError for a name that is no executor or a Reference without config."""
    executor = parse_executor(executor)
    if config is None:
        if not isinstance(plan, PlanResult):
            raise ConfigError("add_executor: give config= with a Reference (only a PlanResult carries its own)")
        config = plan.config
    scene = build_scene(config.scene)
    reference = plan if isinstance(plan, Reference) else reference_from_plan(plan, scene)
    inner = DiagramBuilder()
    landing = None
    match executor:
        case Executor.NONE:
            zero = inner.AddNamedSystem("zero_torque", ConstantVectorSource(np.zeros(plant.num_actuators())))
            inner.ExportOutput(zero.get_output_port(), "actuation")
        case Executor.PAPER:
            add_paper_controller(inner, reference, config)
        case Executor.GRASP:
            add_grasp_controller(inner, scene, execution_schedule(reference, config, scene), config)
        case Executor.GRASP_CLOSED_LOOP | Executor.GRASP_REPLAN:
            description = read_hand(plant, scene_graph, hand, hand_file(config.scene.hand))
            schedule = execution_schedule(reference, config, scene)
            assumed = config.scene.mu if mu_assumed is None else mu_assumed
            landing = add_closed_loop_grasp(inner, plant, hand, box, description, scene, schedule, config, assumed)
    diagram = builder.AddNamedSystem(name, inner.Build())
    return ExecutorSystems(diagram, executor, landing, reference.duration + config.sim.settle_time)


def connect_executor(builder, added: ExecutorSystems, plant, hand, box) -> None:
    """Connects the executor's ports to the plant's of the same quantities (module doc), by name."""
    plant_ports = {
        "box_state": plant.get_state_output_port(box),
        "hand_state": plant.get_state_output_port(hand),
        "contact_results": plant.get_contact_results_output_port(),
        "box_contact_forces": plant.get_generalized_contact_forces_output_port(box),
    }
    for i in range(added.diagram.num_input_ports()):
        port = added.diagram.get_input_port(i)
        builder.Connect(plant_ports[port.get_name()], port)
    builder.Connect(added.GetOutputPort("actuation"), plant.get_actuation_input_port())
