"""An executor as a Diagram that a caller adds to their own DiagramBuilder and wires by port name, as
Drake's MakeHardwareStation users wire their controllers: `add_executor` adds the controller of one
`config.executor.Executor` (and, for a closed-loop one, the contact and object monitors, the estimators
and the reflexes around it: trajectotree.execution.closed_loop, .reflexes; for grasp-replan also the
Replanner: trajectotree.execution.replan) for the caller's plant.

Its ports (F fingers; units m, rad, s, N, N m):
- input `box_state` (6): the object's planar joint [x m, y m, theta rad, xdot m/s, ydot m/s, thetadot rad/s];
- input `hand_state` (4F): the hand's [q rad; v rad/s], finger-major (each finger's joints from its base out);
- closed loop: input `contact_results` (the plant's ContactResults, abstract) and `box_contact_forces` (3: the
  plant's generalized contact forces on the object, f_x N, f_y N in W, torque N m);
- output `actuation` (2F): the joint torques, N m, in the plant's actuation input order;
- closed loop: outputs `mu_estimate` (1), `mass_estimate` (1, kg), `reflex` (1, 0..1), `disturbance` (2, N in W)
  and the contact monitor's per finger (F each) `in_contact` (1/0), `slipping` (1/0), `force_ratio` (1),
  `slip_speed` (m/s) and the object's `tracking_error` (3: measured - planned pose, m, m, rad);
- the grasp executors: output `plan` (abstract: the PlanInEffect the controller follows now,
  trajectotree.execution.in_effect; grasp-replan: the Replanner's, which a replan swaps).
grasp-replan's Replanner reads `box_state`, `hand_state` and the closed loop's estimates inside the
Diagram; a run of it lasts until its plan in effect ends (ExecutorSystems.end_s: a swap moves it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from trajectotree.config import Config, ConfigError
from trajectotree.config.executor import Executor, parse_executor
from trajectotree.execution import closed_loop
from trajectotree.execution.control import ClosedLoopGraspController, GraspController
from trajectotree.execution.impedance import ImpedanceController
from trajectotree.execution.in_effect import PLAN_PORT, PlanInEffect, add_plan_source, plan_in_effect
from trajectotree.execution.reference import Reference, reference_from_plan
from trajectotree.execution.reflexes import ConeFriction, LandingReflex
from trajectotree.results import ClosedLoopLog, PlanResult, ReplanEvent
from trajectotree.scene.hand import HandDescription, hand_file, read_hand
from trajectotree.scene.plant import Scene, build_scene

if TYPE_CHECKING:
    from trajectotree.execution.replan import Replanner

# The closed loop's outputs besides the actuation: what a ClosedLoopLog records.
CLOSED_LOOP_OUTPUTS = ClosedLoopLog.MONITOR_ARRAYS + ("mu_estimate", "mass_estimate", "disturbance", "reflex")


def held_trajectory(times, values, hold: float) -> PiecewisePolynomial:
    """First-order hold through (times, values (K, n)), then constant for `hold` seconds."""
    if hold > 0:
        times = np.append(times, times[-1] + hold)
        values = np.vstack([values, values[-1]])
    return PiecewisePolynomial.FirstOrderHold(times, np.asarray(values).T)


def control_friction(config: Config) -> float:
    """The friction the grasp controller's cones allow: max(search.friction_safety,
    controller.grasp.friction_safety) x scene.mu (never less friction than the plan assumed)."""
    return max(config.search.friction_safety, config.controller.grasp.friction_safety) * config.scene.mu


@dataclass(frozen=True)
class ExecutorSystems:
    """What add_executor added: `diagram`, the executor as one system of the caller's Diagram, with the
    ports the module doc names; the `executor` it runs; the `reference` it starts with; `settle_s`, s,
    the hold after the plan (config.sim.settle_time); grasp-replan's `replanner` (else None)."""

    diagram: Diagram
    executor: Executor
    reference: Reference
    settle_s: float
    replanner: Replanner | None = None

    @property
    def duration(self) -> float:
        """s, the plan's length and the settle time (a replanned run's first plan's: end_s)."""
        return self.reference.duration + self.settle_s

    def reference_in_effect(self, root_context) -> Reference:
        """The reference followed up to now (a replanned run's: the plans spliced at each swap)."""
        if self.replanner is None:
            return self.reference
        return self.replanner.replanning(self.replanner.GetMyContextFromRoot(root_context)).plan.reference

    def end_s(self, root_context) -> float:
        """s, when the run ends: the end of the plan in effect, then the settle time."""
        return self.reference_in_effect(root_context).duration + self.settle_s

    def advance_to_end(self, simulator) -> None:
        """Runs `simulator` (of a Diagram holding this executor) to end_s. A replan moves the end: a
        monitor stops the Simulator after the step in which it moved, and the run goes on to the new end
        (one Simulator throughout, its state untouched)."""
        context = simulator.get_context()
        target = self.end_s(context)
        if self.replanner is not None:

            def moved(root) -> EventStatus:
                if self.end_s(root) != target:
                    return EventStatus.ReachedTermination(self.diagram, "the plan in effect changed")
                return EventStatus.Succeeded()

            simulator.set_monitor(moved)
        while context.get_time() < target:
            simulator.AdvanceTo(target)
            target = self.end_s(context)

    def replans(self, root_context) -> tuple[ReplanEvent, ...]:
        """The replans so far (none but for grasp-replan)."""
        if self.replanner is None:
            return ()
        return self.replanner.replanning(self.replanner.GetMyContextFromRoot(root_context)).events

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


def add_grasp_controller(builder, scene: Scene, config: Config, plan_output) -> None:
    """The open-loop GraspController with the plan's scene (mass, size) and friction (control_friction),
    following the plan of `plan_output` (an output port of a PlanInEffect)."""
    controller = builder.AddNamedSystem(
        "grasp_controller", GraspController(scene, config.controller, mu=control_friction(config))
    )
    builder.Connect(plan_output, controller.plan_port)
    builder.ExportInput(controller.box_state_port, "box_state")
    builder.ExportInput(controller.hand_state_port, "hand_state")
    builder.ExportOutput(controller.actuation_port, "actuation")


def add_estimators(
    builder,
    finger_of_body: dict,
    box_body,
    num_fingers: int,
    time_step: float,
    config: Config,
    *,
    mass: float,
    torque_length: float,
    layout: closed_loop.ObjectLayout = closed_loop.PLANAR_OBJECT,
) -> dict:
    """The closed loop's systems between the plant and a grasp controller, for an object of `layout` (either
    dimension): the cones' friction (reflexes.ConeFriction), the contact and object monitors, the friction and mass
    estimators and the push reflex (closed_loop), wired to each other (export_inputs exports the inputs they share
    with the controller), the plant's `time_step` s the object monitor's period. The plan's scene (config.scene)
    gives the friction they start at and the gravity, `mass` kg is the plan's object's; `torque_length` m turns
    the pose error's angles into metres (FrictionEstimator). Returns them by name: cones, monitor, motion,
    friction, mass, reflex."""
    gains, scene_config = config.controller, config.scene
    cones = builder.AddNamedSystem("cone_friction", ConeFriction(gains, mu_assumed=scene_config.mu))
    monitor = builder.AddNamedSystem(
        "contact_monitor", closed_loop.ContactMonitor(finger_of_body, box_body, num_fingers, gains, layout)
    )
    motion = builder.AddNamedSystem("object_monitor", closed_loop.ObjectMonitor(time_step, layout))
    friction = builder.AddNamedSystem(
        "friction_estimator",
        closed_loop.FrictionEstimator(scene_config.mu, torque_length, num_fingers, gains, layout),
    )
    mass = builder.AddNamedSystem(
        "mass_estimator", closed_loop.MassEstimator(mass, scene_config.gravity, gains, layout)
    )
    reflex = builder.AddNamedSystem("push_reflex", closed_loop.PushReflex(scene_config.gravity, gains, layout))
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
    ):
        builder.Connect(source.GetOutputPort(name), target.GetInputPort(name))
    return {"cones": cones, "monitor": monitor, "motion": motion, "friction": friction, "mass": mass, "reflex": reflex}


def export_inputs(builder, ports: dict) -> None:
    """Exports each list of input ports of `ports` ({name: [ports]}) as one input of that name."""
    for name, targets in ports.items():
        index = builder.ExportInput(targets[0], name)
        for port in targets[1:]:
            builder.ConnectInput(index, port)


def connect_estimates(builder, loop: dict, controller) -> None:
    """Feeds the estimates of `loop` (add_estimators') to a closed-loop grasp controller's inputs of the same
    names (the cones' `friction`, `mass_estimate`, `reflex`, `disturbance`)."""
    for source, name in (
        (loop["cones"], "friction"),
        (loop["mass"], "mass_estimate"),
        (loop["reflex"], "reflex"),
        (loop["reflex"], "disturbance"),
    ):
        builder.Connect(source.GetOutputPort(name), controller.GetInputPort(name))


def export_estimates(builder, loop: dict) -> None:
    """Exports the outputs of `loop` (add_estimators') that a ClosedLoopLog records (CLOSED_LOOP_OUTPUTS)."""
    for name in ClosedLoopLog.MONITOR_ARRAYS:
        builder.ExportOutput(loop["monitor"].GetOutputPort(name), name)
    builder.ExportOutput(loop["friction"].GetOutputPort("mu_estimate"), "mu_estimate")
    builder.ExportOutput(loop["mass"].GetOutputPort("mass_estimate"), "mass_estimate")
    for name in ("disturbance", "reflex"):
        builder.ExportOutput(loop["reflex"].GetOutputPort(name), name)


def add_closed_loop_grasp(
    builder, plant, hand, box, description: HandDescription, scene: Scene, config: Config
) -> dict:
    """The ClosedLoopGraspController and around it the closed loop's estimators (add_estimators) and the landing
    reflex (trajectotree.execution.reflexes), wired to each other and to the exported inputs. Returns the systems
    whose input `plan` the caller connects, by name."""
    gains = config.controller
    controller = builder.AddNamedSystem(
        "grasp_controller", ClosedLoopGraspController(scene, gains, mu=control_friction(config))
    )
    landing = builder.AddNamedSystem("landing_reflex", LandingReflex(scene, gains))
    finger_of_body = closed_loop.planar_finger_of_body(plant, hand, description)
    box_body = plant.GetBodyByName("box", box).index()
    loop = add_estimators(
        builder,
        finger_of_body,
        box_body,
        scene.num_fingers,
        plant.time_step(),
        config,
        mass=config.scene.box_mass,
        torque_length=config.scene.shape.circumradius,
    )
    monitor, motion = loop["monitor"], loop["motion"]
    box_state = [controller.box_state_port, landing.box_state_port, monitor.box_state_port, motion.box_state_port]
    export_inputs(
        builder,
        {
            "box_state": box_state,
            "hand_state": [controller.hand_state_port, landing.hand_state_port],
            "contact_results": [monitor.contact_results_port],
            "box_contact_forces": [motion.box_contact_forces_port],
        },
    )
    for source, name in ((loop["friction"], "mu_estimate"), (loop["reflex"], "reflex")):
        builder.Connect(source.GetOutputPort(name), landing.GetInputPort(name))
    builder.Connect(landing.GetOutputPort("clocks"), controller.GetInputPort("clocks"))
    connect_estimates(builder, loop, controller)
    builder.ExportOutput(controller.actuation_port, "actuation")
    export_estimates(builder, loop)
    return {
        "followers": (controller, landing, monitor, loop["friction"]),
        "monitor": monitor,
        "friction": loop["friction"],
        "mass": loop["mass"],
    }


def add_replanner(builder, plan: PlanResult, config: Config, initial: PlanInEffect, loop: dict, segment_workers):
    """The Replanner of `plan` (trajectotree.execution.replan), reading the measured state (the exported
    inputs) and the closed loop's estimates (the systems `loop` of add_closed_loop_grasp); its plan
    output feeds every system that follows the plan."""
    # Here, not at the top: the replanner loads the planner (search, cito), which no other executor needs.
    from trajectotree.execution.replan import PlanePlanning, Replanner

    planning = PlanePlanning(plan, config, build_scene(config.scene), segment_workers)
    return connect_replanner(builder, Replanner(planning, initial), loop)


def connect_replanner(builder, replanner: Replanner, loop: dict) -> Replanner:
    """Adds `replanner` (either dimension's) to `builder`, reading the exported inputs `box_state` and
    `hand_state` and the estimates of `loop` (the closed loop's systems: monitor, friction, mass)."""
    replanner = builder.AddNamedSystem("replanner", replanner)
    builder.ConnectInput("box_state", replanner.box_state_port)
    builder.ConnectInput("hand_state", replanner.hand_state_port)
    for source, name in (
        (loop["monitor"], "tracking_error"),
        (loop["monitor"], "in_contact"),
        (loop["friction"], "mu_estimate"),
        (loop["mass"], "mass_estimate"),
    ):
        builder.Connect(source.GetOutputPort(name), replanner.GetInputPort(name))
    return replanner


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
    name: str = "executor",
    segment_workers: int | None = None,
) -> ExecutorSystems:
    """Adds the executor `executor` (an Executor or its name) of `plan` (a PlanResult, or a Reference
    with `config`) to `builder` as one Diagram named `name`, for the caller's finalized `plant` (with
    its `scene_graph` and the `hand` and `box` model instances, as scene.plant.add_hand_and_box adds them
    to a plant of the plan's scene): its ports are left for the caller to connect by name (units and
    sizes: module doc). Inputs: `box_state` (6: the object's planar [x, y, theta] m, m, rad and their
    rates), `hand_state` (4F: [q rad; v rad/s]) and, closed loop, `contact_results` (the plant's) and
    `box_contact_forces` (3: N, N, N m on the object). Outputs: `actuation` (2F joint torques, N m);
    closed loop: `mu_estimate`, `mass_estimate` (kg), `reflex` (0..1), `disturbance` (N in W), per finger
    `in_contact`, `slipping`, `force_ratio` and `slip_speed` (m/s), and `tracking_error` (m, m, rad);
    the grasp executors: `plan` (abstract, the PlanInEffect followed now).
    The controller assumes the plan's scene (`config.scene`: its friction and mass), whatever the plant's.
    The zero-torque executor has only its `actuation` output. grasp-replan (a PlanResult only: the
    planner needs its goal) also adds the Replanner (trajectotree.execution.replan; a new plan's later
    segments on `segment_workers` local processes, None: as planning.planners.plan); simulate it to its
    ExecutorSystems.end_s, which a replan moves (ExecutorSystems.advance_to_end). ConfigError for a
    name that is no executor, a Reference without config or a Reference to replan."""
    executor = parse_executor(executor)
    if config is None:
        if not isinstance(plan, PlanResult):
            raise ConfigError("add_executor: give config= with a Reference (only a PlanResult carries its own)")
        config = plan.config
    if executor.replans and not isinstance(plan, PlanResult):
        raise ConfigError(
            f"add_executor(executor={executor.value!r}): give the PlanResult (the planner needs its goal)"
        )
    scene = build_scene(config.scene)
    reference = plan if isinstance(plan, Reference) else reference_from_plan(plan, scene)
    inner = DiagramBuilder()
    replanner = None
    match executor:
        case Executor.NONE:
            zero = inner.AddNamedSystem("zero_torque", ConstantVectorSource(np.zeros(plant.num_actuators())))
            inner.ExportOutput(zero.get_output_port(), "actuation")
        case Executor.PAPER:
            add_paper_controller(inner, reference, config)
        case Executor.GRASP:
            source = add_plan_source(inner, plan_in_effect(reference, config, scene, config.scene.mu))
            add_grasp_controller(inner, scene, config, source.get_output_port())
            inner.ExportOutput(source.get_output_port(), PLAN_PORT)
        case Executor.GRASP_CLOSED_LOOP | Executor.GRASP_REPLAN:
            description = read_hand(plant, scene_graph, hand, hand_file(config.scene.hand))
            loop = add_closed_loop_grasp(inner, plant, hand, box, description, scene, config)
            initial = plan_in_effect(reference, config, scene, config.scene.mu)
            if executor.replans:
                replanner = add_replanner(inner, plan, config, initial, loop, segment_workers)
                plan_output = replanner.plan_port
            else:
                plan_output = add_plan_source(inner, initial).get_output_port()
            for follower in loop["followers"]:
                inner.Connect(plan_output, follower.plan_port)
            inner.ExportOutput(plan_output, PLAN_PORT)
    diagram = builder.AddNamedSystem(name, inner.Build())
    return ExecutorSystems(diagram, executor, reference, config.sim.settle_time, replanner)


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
