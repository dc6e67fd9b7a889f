"""The closed loop in space (issue 37 item 2): the planar monitors, estimators and push reflex with the cube's
layout (closed_loop.SPACE_OBJECT) around the grasp controller in space (space_control.SpaceClosedLoopGraspController,
space_run.add_space_executor): the pose error from quaternions, the friction estimate of a steady slide, the
friction and mass estimates of a static hold in a world the plan did not assume, the push's disturbance, one plan
executed closed loop from the command line, and an executor space lacks refused."""

import dataclasses
import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from test_space_execution import _initial_grasp_hold

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError
from trajectotree.execution.closed_loop import SPACE_OBJECT, FrictionEstimator
from trajectotree.execution.in_effect import PlanInEffect
from trajectotree.execution.space_control import space_plan_in_effect
from trajectotree.execution.space_run import add_space_executor, simulate_space
from trajectotree.execution.world import Conditions, Push
from trajectotree.geometry import matrix_quaternions, quaternion_matrices, so3_exp
from trajectotree.results import CLOSED_LOOP_ARRAYS
from trajectotree.scene.spatial import build_space_scene

MASS = 0.094  # kg, fingerpro4's cube


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def no_settle() -> Config:
    config = Config()
    return dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.0))


@pytest.fixture(scope="module")
def hold(scene):
    """The search's initial grasp of the cube held still for 0.8 s (test_space_execution._initial_grasp_hold)."""
    return _initial_grasp_hold(scene, 0.8)


def test_the_pose_error_in_space_is_measured_minus_planned():
    """SPACE_OBJECT.pose_error: the rotation vector e with R = exp([e]x) R_plan, then the centre's offset, in the
    velocities' layout [w, v]; the quaternion's sign and scale do not matter."""
    rng = np.random.default_rng(1)
    q_plan = rng.normal(size=4)
    q_plan /= np.linalg.norm(q_plan)
    turn = np.array([0.1, -0.2, 0.05])  # rad, in W
    q = matrix_quaternions(so3_exp(turn) @ quaternion_matrices(q_plan))
    schedule = SimpleNamespace(x=np.array([np.concatenate([q_plan, [0.01, 0.0, 0.0]])]))  # a schedule's poses
    state = np.concatenate([-2.0 * q, [0.01, 0.003, -0.002], np.zeros(6)])  # -2 q: the same rotation
    np.testing.assert_allclose(SPACE_OBJECT.pose_error(state, schedule, 0), [*turn, 0.0, 0.003, -0.002], atol=1e-12)
    np.testing.assert_allclose(SPACE_OBJECT.error_scale(0.05), [0.05] * 3 + [1.0] * 3)
    np.testing.assert_allclose(SPACE_OBJECT.gravity_W(9.81), [0.0, 0.0, -9.81])


def _estimate_after_slide(scene, hold, ratios, tracking_error) -> np.ndarray:
    """The FrictionEstimator of the cube's layout fed a steady slide of finger 0 (pushing 1 N, its ratio |f_t| / f_n
    running through `ratios`, one per control period) while the cube is `tracking_error` (6) off the plan: its
    estimates, one per period."""
    config = no_settle()
    gains = config.controller
    estimator = FrictionEstimator(config.scene.mu, float(np.linalg.norm(scene.object.half)), 4, gains, SPACE_OBJECT)
    context = estimator.CreateDefaultContext()
    plan: PlanInEffect = space_plan_in_effect(hold, config, scene)
    estimator.GetInputPort("plan").FixValue(context, plan)
    for name, value in (
        ("slipping", [1.0, 0.0, 0.0, 0.0]),
        ("normal_force", [1.0, 2.0, 2.0, 2.0]),
        ("approach_speed", np.zeros(4)),
        ("reflex", [0.0]),
        ("tracking_error", tracking_error),
    ):
        estimator.GetInputPort(name).FixValue(context, np.asarray(value, dtype=float))
    ratio_port = estimator.GetInputPort("force_ratio")
    simulator = Simulator(estimator, context)
    estimates = []
    for k, ratio in enumerate(ratios):
        ratio_port.FixValue(context, np.array([ratio, 0.3, 0.3, 0.3]))
        simulator.AdvanceTo((k + 1) / gains.rate_hz)
        estimates.append(estimator.GetOutputPort("mu_estimate").Eval(context)[0])
    return np.array(estimates)


def test_the_friction_estimate_in_space_falls_to_a_steady_slide_s_ratio(scene, hold):
    """A loaded contact that slides steadily at ratios about 0.4 for longer than slip_confirm_time: the estimate
    falls from the plan's 0.7 to the slide's median and never rises; the fingers that stick (slipping 0) say nothing.
    With the cube turned 0.2 rad off its plan (11 mm at its rim, past friction_evidence_error), the slide is no
    evidence: the estimate stays at 0.7."""
    ratios = 0.4 + 0.02 * np.sin(np.arange(40))  # a steady slide's scatter about 0.4
    on_plan = _estimate_after_slide(scene, hold, ratios, np.zeros(6))
    assert np.all(np.diff(on_plan) <= 0.0) and on_plan[0] == pytest.approx(0.7)
    assert on_plan[-1] == pytest.approx(0.4, abs=0.02)
    turned = _estimate_after_slide(scene, hold, ratios, [0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert np.all(turned == pytest.approx(0.7))


def test_a_hold_in_a_world_of_lower_friction_is_kept_at_the_estimate(scene, hold):
    """The initial grasp held where the world's friction is 0.3, not the plan's 0.7 (the open loop drops the cube
    there: its cones allow 0.56): the contacts slide, the estimate falls to within 0.03 of 0.3, and the cube stays
    within 5 mm and 5 deg of its pose."""
    result = simulate_space(hold, no_settle(), scene, executor="grasp-closed-loop", conditions=Conditions(mu=0.3))
    loop = result.closed_loop
    assert loop is not None and not result.dropped
    assert loop.mu_estimate[0] == pytest.approx(0.7)
    assert np.all(np.diff(loop.mu_estimate) <= 0.0)
    assert loop.mu_estimate[-1] == pytest.approx(0.3, abs=0.03)
    assert loop.slipping.any()
    assert result.position_error_m.max() < 5e-3 and np.degrees(result.orientation_error_rad.max()) < 5.0
    assert result.to_json()["closed_loop"]["mu_estimate"] == loop.mu_estimate[-1]


def test_the_mass_estimate_of_a_cube_half_again_as_heavy(scene, hold):
    """The initial grasp of a cube 1.5 x the plan's mass: the estimate starts at the plan's 94 g and reaches the
    simulated 141 g within 3 % over the last 0.2 s (its filter's time constant 0.2 s); the cube, which sags under
    the plan's mass open loop, stays nearer its planned centre closed loop."""
    heavy = Conditions(mass=1.5 * MASS)
    closed = simulate_space(hold, no_settle(), scene, executor="grasp-closed-loop", conditions=heavy)
    estimate = closed.closed_loop.mass_estimate
    assert estimate[0] == pytest.approx(MASS)
    np.testing.assert_allclose(estimate[closed.t > 0.6], 1.5 * MASS, rtol=0.03)
    open_loop = simulate_space(hold, no_settle(), scene, conditions=heavy)
    assert not closed.dropped and not open_loop.dropped
    late = closed.t > 0.5
    sag = closed.position_error_m[late].mean(), open_loop.position_error_m[late].mean()
    assert sag[0] < 0.5 * sag[1], sag


def test_a_horizontal_push_is_measured_and_cancelled(scene, hold):
    """A 1 N push along +x for 0.2 s (about the cube's weight, 0.92 N): the disturbance the loop measures is the
    push, the reflex is on while it acts, and the cube stays within 1 mm of its pose; open loop it gives way by more
    than 3 mm."""
    push = Conditions(push=Push(force=(1.0, 0.0), time_s=0.3, duration_s=0.2))
    result = simulate_space(hold, no_settle(), scene, executor="grasp-closed-loop", conditions=push)
    loop, t = result.closed_loop, result.t
    during = (t > 0.31) & (t < 0.5)
    np.testing.assert_allclose(loop.disturbance[during], np.tile([1.0, 0.0, 0.0], (during.sum(), 1)), atol=0.05)
    assert np.all(loop.reflex[t < 0.3] == 0.0) and np.all(loop.reflex[(t > 0.32) & (t < 0.5)] == 1.0)
    assert not result.dropped and result.position_error_m.max() < 1e-3
    assert simulate_space(hold, no_settle(), scene, conditions=push).position_error_m.max() > 3e-3
    assert np.all(loop.mu_estimate == pytest.approx(0.7))  # a pushed grasp's slides are no evidence


def test_the_space_executor_s_closed_loop_ports(scene, hold):
    """add_space_executor(executor="grasp-closed-loop"): the inputs the plant feeds and the estimates it exports, by
    name, in the cube's sizes; an executor space lacks (paper) is a ConfigError naming it and the choices."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig

    from trajectotree.scene.spatial import add_space_object

    config = no_settle()
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=config.sim.time_step), builder)
    Parser(plant).AddModels(scene.hand_file.model)
    add_space_object(plant, scene.object)
    plant.Finalize()
    executor = add_space_executor(builder, plant, hold, config, scene, executor="grasp-closed-loop")
    inputs = {executor.get_input_port(i).get_name(): executor.get_input_port(i).size() for i in range(4)}
    assert inputs == {"box_state": 13, "hand_state": 24, "contact_results": 0, "box_contact_forces": 6}
    outputs = {executor.get_output_port(i).get_name() for i in range(executor.num_output_ports())}
    assert outputs == {"actuation", "plan", *CLOSED_LOOP_ARRAYS}
    assert executor.GetOutputPort("disturbance").size() == 3 and executor.GetOutputPort("tracking_error").size() == 6
    with pytest.raises(ConfigError, match="executor = 'paper' does not execute plans in space yet"):
        add_space_executor(DiagramBuilder(), plant, hold, config, scene, executor="paper")


@pytest.mark.slow
def test_a_plan_in_space_executes_closed_loop_without_a_drop(space_plan, tmp_path, capsys):
    """`simulate PLAN_DIR --executor grasp-closed-loop`: held within 3 deg and 3 mm of the goal, the estimates
    where the plan's world puts them, sim.json's closed_loop and sim.npz's closed-loop arrays in the cube's sizes."""
    plan = tmp_path / "plan"
    shutil.copytree(space_plan, plan)
    assert main(["simulate", str(plan), "--executor", "grasp-closed-loop"]) == 0
    out = capsys.readouterr().out
    assert "held" in out and "closed loop: friction estimate" in out
    summary = json.loads((plan / "sim.json").read_text())
    assert summary["executor"] == "grasp-closed-loop" and not summary["dropped"]
    assert summary["final_orientation_error_rad"] < np.radians(3.0) and summary["final_position_error_m"] < 3e-3
    assert summary["closed_loop"]["mass_estimate"] == pytest.approx(MASS, rel=0.05)
    assert summary["closed_loop"]["mu_estimate"] > 0.5
    with np.load(plan / "sim.npz") as s:
        K = len(s["t"])
        assert s["tracking_error"].shape == (K, 6) and s["disturbance"].shape == (K, 3)
        assert s["in_contact"].shape == (K, 4) and s["mu_estimate"].shape == (K,)


@pytest.mark.slow  # the shared plan
def test_an_executor_space_lacks_exits_2(space_plan, capsys):
    before = sorted(p.name for p in space_plan.iterdir())
    assert main(["simulate", str(space_plan), "--executor", "paper"]) == 2
    err = capsys.readouterr().err
    assert "--executor = 'paper' does not execute plans in space yet" in err
    assert "grasp, grasp-closed-loop, grasp-replan, none" in err
    assert sorted(p.name for p in space_plan.iterdir()) == before  # nothing written, no lock left
