"""The closed loop around the grasp controller (trajectotree.execution.closed_loop): the contact
watch on a static hold that slips, the friction and mass estimates against the simulated
world, the push reflex, the files and the command, and the open loop left exactly as it was."""

import json

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, ControllerGains, EstimatorGains, with_values
from trajectotree.config.executor import Executor
from trajectotree.execution.reference import static_hold_reference
from trajectotree.execution.run import run_simulation
from trajectotree.execution.simulate import simulate_reference
from trajectotree.execution.world import Conditions, Push
from trajectotree.io import load_sim, save_sim
from trajectotree.results import CLOSED_LOOP_ARRAYS
from trajectotree.scene.plant import build_scene

# Two fingers under the box and two above, 4 cm in from the corners (tests/execution/test_control.py).
HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def hold_config(gains: dict | None = None) -> Config:
    """The defaults with no settling and the controller fields `gains` names by path ("estimators.friction_floor")."""
    return with_values(Config(), {"sim.settle_time": 0.0} | {f"controller.{k}": v for k, v in (gains or {}).items()})


def three_finger_hold(scene, lifted: int, duration: float = 0.6):
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=duration, lifted=lifted)
    assert reference is not None
    return reference


def test_closed_loop_ports_are_named(scene):
    """What a replanner reads: the monitor's, the estimators' and the reflex's output ports by name."""
    from trajectotree.execution.simulate import build_execution_diagram

    execution = build_execution_diagram(three_finger_hold(scene, 0), hold_config(), executor=Executor.GRASP_CLOSED_LOOP)
    diagram = execution.executor.diagram  # the executor's own Diagram (trajectotree.execution.executor)
    names = lambda system: [system.get_output_port(i).get_name() for i in range(system.num_output_ports())]  # noqa: E731
    monitor = diagram.GetSubsystemByName("contact_monitor")
    assert names(monitor) == [
        "in_contact",
        "slipping",
        "force_ratio",
        "normal_force",
        "slip_speed",
        "approach_speed",
        "tracking_error",
    ]
    assert names(diagram.GetSubsystemByName("object_monitor")) == ["acceleration", "contact_force"]
    assert names(diagram.GetSubsystemByName("friction_estimator")) == ["mu_estimate"]
    assert names(diagram.GetSubsystemByName("mass_estimator")) == ["mass_estimate"]
    assert names(diagram.GetSubsystemByName("push_reflex")) == ["disturbance", "reflex"]
    controller = diagram.GetSubsystemByName("grasp_controller")
    inputs = [controller.get_input_port(i).get_name() for i in range(controller.num_input_ports())]
    assert inputs == ["box_state", "hand_state", "plan", "friction", "mass_estimate", "reflex", "disturbance", "clocks"]
    assert names(diagram.GetSubsystemByName("landing_reflex")) == ["clocks"]
    assert names(diagram.GetSubsystemByName("cone_friction")) == ["friction"]
    assert set(execution.closed_loop_loggers) == set(CLOSED_LOOP_ARRAYS)


def tip_travel_along_the_box(scene, result) -> np.ndarray:
    """(4,) m, how far each fingertip centre moved in the box frame over the run: a sliding
    contact carries its finger along the face, a sticking one (rolling at most) stays put."""
    from trajectotree.geometry import poses_world_to_box

    tips = np.array([scene.fingertip_positions(q) for q in result.q])
    p_B = poses_world_to_box(result.x, tips)
    return np.abs(p_B[-1] - p_B[0]).max(axis=1)


@pytest.fixture(scope="module")
def slipping_run(scene):
    """0.6 s of fingers 0, 2, 3 holding the box at friction 0.45 while the controller keeps the
    plan's cones (the friction estimate's floor at the plan's 0.7, so the estimate cannot act)."""
    reference = three_finger_hold(scene, lifted=1)
    return simulate_reference(
        reference,
        hold_config({"estimators.friction_floor": 0.7}),
        conditions=Conditions(mu=0.45),
        executor=Executor.GRASP_CLOSED_LOOP,
    )


def test_a_three_finger_hold_at_lowered_friction_reports_the_slipping_finger(scene, slipping_run):
    """slipping_run: finger 2's contact slides along the top face, the watch says so, and only
    for finger 2."""
    result = slipping_run
    watch = result.closed_loop
    assert watch is not None and not result.dropped
    dt = result.t[1] - result.t[0]
    slid = watch.slipping.sum(axis=0) * dt  # s per finger
    assert slid[2] > 0.2, slid
    assert slid[[0, 1, 3]].max() <= 0.02, slid
    assert not watch.in_contact[:, 1].any()  # the lifted finger never touches
    assert watch.in_contact[result.t > 0.05][:, [0, 2, 3]].all()
    # The truth, from the simulated motion alone: finger 2 travelled along the box, the others did not.
    travel = tip_travel_along_the_box(scene, result)
    assert travel[2] > 0.01 and travel[[0, 3]].max() < 1e-3, travel
    # Sliding means riding the friction cone: finger 2's ratio is the world's friction while it slides.
    sliding = watch.slipping[:, 2]
    assert np.median(watch.force_ratio[sliding, 2]) == pytest.approx(0.45, abs=0.03)
    assert np.all(watch.mu_estimate == 0.7)  # held at the floor: nothing estimated
    assert np.all(watch.slip_speed[sliding, 2] > Config().controller.estimators.slip_speed)


@pytest.mark.parametrize("mu, lifted", [(0.45, 1), (0.3, 0)])
def test_the_friction_estimate_of_a_scripted_slip_is_the_simulated_friction(scene, mu, lifted):
    """The controller starts at the plan's friction (0.7, cones 0.56) on a three-finger hold
    that needs more than the world's `mu`: a contact slides, the estimate drops to within 0.05
    of `mu` (never rising), and the grasp QP's cones, which follow it over cone_time_constant,
    then keep the contacts sticking."""
    result = simulate_reference(
        three_finger_hold(scene, lifted),
        hold_config(),
        conditions=Conditions(mu=mu),
        executor=Executor.GRASP_CLOSED_LOOP,
    )
    watch = result.closed_loop
    assert watch.mu_estimate[0] == pytest.approx(0.7)
    assert np.all(np.diff(watch.mu_estimate) <= 0.0)
    assert watch.mu_estimate[-1] == pytest.approx(mu, abs=0.05)
    assert not result.dropped
    late = result.t > 0.1 + 2 * Config().controller.grasp.cone_time_constant
    assert not watch.slipping[late].any()  # the QP's cones at the estimate: no more sliding
    assert result.to_json()["closed_loop"]["mu_estimate"] == watch.mu_estimate[-1]


def test_the_friction_estimate_stops_at_the_floor(scene):
    result = simulate_reference(
        three_finger_hold(scene, 0),
        hold_config({"estimators.friction_floor": 0.5}),
        conditions=Conditions(mu=0.3),
        executor=Executor.GRASP_CLOSED_LOOP,
    )
    assert result.closed_loop.mu_estimate.min() == pytest.approx(0.5)


def test_the_mass_estimate_of_a_box_held_at_twice_the_mass(scene):
    """Four fingers hold a box twice as heavy as planned: the mass estimate reaches the simulated
    mass within 10 %, and the box, which sags under the plan's mass, hangs where planned."""
    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=1.0)
    heavy = Conditions(mass=2.0 * scene.config.box_mass)
    closed = simulate_reference(reference, hold_config(), conditions=heavy, executor=Executor.GRASP_CLOSED_LOOP)
    estimate = closed.closed_loop.mass_estimate
    assert estimate[0] == pytest.approx(scene.config.box_mass)
    late = closed.t > 0.6
    np.testing.assert_allclose(estimate[late], 2.0 * scene.config.box_mass, rtol=0.1)
    open_loop = simulate_reference(reference, hold_config(), conditions=heavy)
    sag = lambda r: np.mean(r.x_plan[late, 1] - r.x[late, 1])  # noqa: E731
    assert sag(closed) < 0.5 * sag(open_loop), (sag(closed), sag(open_loop))
    assert not closed.dropped


def test_the_push_reflex_squeezes_while_a_push_acts_and_lets_go_after(scene):
    """A 1.5 N push (3 x the box's weight) along +x for 0.1 s: the disturbance the loop
    measures is the push, the reflex is on within 10 ms and off once the push has been gone
    for reflex_hold + reflex_release; no reflex before the push."""
    gains = ControllerGains()
    push = Push(force=(1.5, 0.0), time_s=0.3, duration_s=0.1)
    result = simulate_reference(
        three_finger_hold(scene, 0, duration=1.0),
        hold_config(),
        conditions=Conditions(push=push),
        executor=Executor.GRASP_CLOSED_LOOP,
    )
    watch, t = result.closed_loop, result.t
    assert not result.dropped
    during = (t > 0.31) & (t < 0.4)
    np.testing.assert_allclose(watch.disturbance[during], np.tile([1.5, 0.0], (during.sum(), 1)), atol=0.05)
    assert np.all(watch.reflex[t < 0.3] == 0.0)
    assert np.all(watch.reflex[(t >= 0.31) & (t < 0.4 + gains.push_reflex.hold)] == 1.0)
    assert np.all(watch.reflex[t > 0.4 + gains.push_reflex.hold + gains.push_reflex.release + 0.01] == 0.0)
    quiet = (t > 0.05) & ((t < 0.3) | (t > 0.41))
    assert np.abs(watch.disturbance[quiet]).max() < 0.05  # the contacts and gravity explain the rest
    assert np.all(watch.mu_estimate == 0.7)  # a pushed grasp's slides are no evidence of the friction


def test_the_reflex_holds_a_three_finger_grasp_against_a_push_it_would_give_way_to(scene):
    """A 3 N push (6 x the box's weight) along +x for 0.2 s on a three-finger hold: the reflex
    that cancels the measured disturbance at once, with its cones at the friction estimate,
    keeps the box within 3 mm of its pose; without those (the squeeze and gains alone) it gave
    way by 8 mm, and the open loop by 33 mm."""
    push = Conditions(push=Push(force=(3.0, 0.0), time_s=0.3, duration_s=0.2))
    reference = three_finger_hold(scene, 0, duration=0.8)
    squeeze_only = hold_config(
        {
            "push_reflex.disturbance_feedforward": 0.0,
            "push_reflex.torque_weight": 1.0,
            "push_reflex.friction_safety": 0.8,
        }
    )
    error = lambda r: np.abs(r.x - r.x_plan).max(axis=0)  # noqa: E731
    held = simulate_reference(reference, hold_config(), conditions=push, executor=Executor.GRASP_CLOSED_LOOP)
    gave_way = simulate_reference(reference, squeeze_only, conditions=push, executor=Executor.GRASP_CLOSED_LOOP)
    assert not held.dropped
    assert error(held)[0] < 0.003 and error(held)[2] < 0.01, error(held)
    assert error(gave_way)[0] > 0.005, error(gave_way)


@pytest.mark.slow
def test_a_planned_goal_pushed_mid_segment_with_3_n_is_held_closed_loop():
    """Goal 2.2 pushed along +x with 3 N for 0.2 s in the middle of its middle segment (finger 1
    mid-swing, the three others holding), as the sweep's push-3N condition does: the closed loop
    holds it and ends on the goal (main's reflex, squeeze and gains alone, lost the box)."""
    from trajectotree.experiments.conditions import middle_of_middle_segment
    from trajectotree.planning.planners import plan

    result = plan(goal=2.2)
    assert result.success, result.status
    config = result.config
    start = middle_of_middle_segment(config, float(result.trajectory.t[-1]))
    push = Push(force=(3.0, 0.0), time_s=start, duration_s=config.sim.push_duration)
    run = run_simulation(plan=result, push=push, executor="grasp-closed-loop")
    assert not run.dropped
    assert run.closed_loop.reflex[(run.t > start + 0.01) & (run.t < start + push.duration_s)].min() == 1.0
    assert run.final_error[2] < np.radians(3.0)
    pushed = (run.t >= start) & (run.t < start + 0.5)
    assert np.abs(run.x - run.x_plan)[pushed, 0].max() < 0.01  # it gives way by millimetres, not centimetres


def test_open_loop_runs_are_unchanged_bit_for_bit(scene):
    """With the closed loop off, a run is the one main made before the closed loop existed
    (tests/execution/data/open_loop_hold.npz: main at 816ba79, a three-finger hold at friction
    0.5 pushed with 0.3 N): the same numbers, to the last bit, and no closed-loop systems."""
    from pathlib import Path

    from trajectotree.execution.simulate import build_execution_diagram

    reference = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=0.5, lifted=0)
    conditions = Conditions(mu=0.5, push=Push(force=(0.3, 0.0), time_s=0.2, duration_s=0.1))
    result = simulate_reference(reference, hold_config(), conditions=conditions)
    with np.load(Path(__file__).parent / "data" / "open_loop_hold.npz") as golden:
        for name in ("t", "x", "q", "f_W", "abs_error"):
            np.testing.assert_array_equal(getattr(result, name), golden[name], err_msg=name)
    assert result.closed_loop is None and result.to_json()["closed_loop"] is None
    diagram = build_execution_diagram(reference, hold_config(), conditions=conditions).executor.diagram
    names = {diagram.GetSystems()[i].get_name() for i in range(len(diagram.GetSystems()))}
    assert not names & {"contact_monitor", "object_monitor", "friction_estimator", "mass_estimator", "push_reflex"}


def test_closed_loop_files_round_trip_and_the_forces_figure_marks_slips(slipping_run, tmp_path):
    from trajectotree.figures.run import figure_finger_forces, slip_intervals

    result = slipping_run
    save_sim(result, tmp_path)
    with np.load(tmp_path / "sim.npz") as data:
        assert set(CLOSED_LOOP_ARRAYS) <= set(data.files)
    loaded = load_sim(tmp_path)
    for name in CLOSED_LOOP_ARRAYS:
        np.testing.assert_array_equal(getattr(loaded.closed_loop, name), getattr(result.closed_loop, name))
    summary = json.loads((tmp_path / "sim.json").read_text())["closed_loop"]
    assert summary == loaded.to_json()["closed_loop"]
    assert summary["slipping_s"][2] > 0.1 and summary["mu_estimate"] == 0.7
    spans = slip_intervals(result.t, result.closed_loop.slipping[:, 2])
    assert spans and all(b > a for a, b in spans)
    fig = figure_finger_forces(result)
    hatched = [[p for p in ax.patches if p.get_hatch()] for ax in fig.axes]
    assert len(hatched[2]) == len(spans) and not hatched[1]


def test_slip_intervals_are_the_runs_of_samples():
    from trajectotree.figures.run import slip_intervals

    t = np.arange(6) * 0.1
    assert slip_intervals(t, [0, 1, 1, 0, 1, 1]) == [(t[1], t[3]), (t[4], t[5])]
    assert slip_intervals(t, np.zeros(6)) == []


def test_the_closed_loop_needs_the_grasp_controller(scene):
    """Eq. 20 with the closed loop is no executor: the older options that would combine them are refused."""
    from trajectotree.config.executor import executor_of

    with pytest.raises(ConfigError, match="controller = 'paper': the closed loop runs around the grasp controller"):
        executor_of("paper", closed_loop=True)
    with pytest.raises(ConfigError, match="executor = 'paper-closed-loop' is not an executor; valid: grasp, grasp-"):
        run_simulation(plan=three_finger_hold(scene, 0), config=hold_config(), executor="paper-closed-loop")


@pytest.mark.parametrize("floor", [0.0, -0.1, 1.5, float("nan")])
def test_a_friction_floor_outside_0_1_is_refused(floor):
    with pytest.raises(ConfigError, match=r"controller.estimators.friction_floor = .* valid range: \(0, 1\]"):
        EstimatorGains(friction_floor=floor)


def test_simulate_command_closed_loop(scene, tmp_path, capsys):
    """`simulate --closed-loop` records what the loop saw (sim.json's closed_loop, the arrays in
    sim.npz) and says it; without the option sim.json's closed_loop is null."""
    from test_simulate import hold_plan_arrays, write_plan_dir

    config = hold_config()
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), config)
    forces = tmp_path / "forces.png"
    assert main(["simulate", str(plan_dir), "--closed-loop", "--forces", str(forces)]) == 0
    out = capsys.readouterr().out
    assert "closed loop: friction estimate 0.700 (plan 0.7), mass estimate" in out
    summary = json.loads((plan_dir / "sim.json").read_text())
    assert summary["closed_loop"]["mass_estimate"] == pytest.approx(0.05, rel=0.05)
    with np.load(plan_dir / "sim.npz") as data:
        assert set(CLOSED_LOOP_ARRAYS) <= set(data.files)
    assert forces.read_bytes()[:4] == b"\x89PNG"
    assert main(["simulate", str(plan_dir), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["closed_loop"] is None


@pytest.mark.parametrize(
    "options, named",
    [
        (
            ["--closed-loop", "--friction-floor", "0"],
            "(controller.estimators.friction_floor) = 0.0 is out of range; valid range: (0, 1]",
        ),
        (
            ["--closed-loop", "--friction-floor", "1.5"],
            "--friction-floor (controller.estimators.friction_floor) = 1.5 is out of range",
        ),
        (["--closed-loop", "--controller", "paper"], "controller = 'paper': the closed loop runs around the grasp"),
    ],
)
def test_simulate_command_refuses_bad_closed_loop_options(scene, tmp_path, capsys, options, named):
    from test_simulate import hold_plan_arrays, write_plan_dir

    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), hold_config())
    assert main(["simulate", str(plan_dir), *options]) == 2
    assert named in capsys.readouterr().err
    assert not (plan_dir / "sim.json").exists() and not (plan_dir / "sim.npz").exists()
