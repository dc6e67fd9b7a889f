"""The execution pipeline: references from plan arrays, the simulation result and
its files, the `simulate` command (including bad input), playback files."""

import dataclasses
import json

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import Config, config_to_dict
from trajectotree.config.executor import Executor
from trajectotree.execution.executor import held_trajectory
from trajectotree.execution.impedance import ImpedanceController
from trajectotree.execution.reference import check_plan_arrays, reference_from_arrays, static_hold_reference
from trajectotree.execution.run import run_simulation
from trajectotree.execution.simulate import simulate_reference
from trajectotree.io import load_sim, save_sim
from trajectotree.scene.plant import build_scene

HOLD_ARCLENGTHS = (0.56, 0.14, 0.26, 0.44)
SIM_JSON_KEYS = {"mae_x", "mae_y", "mae_theta", "final_error", "dropped", "drop_time_s", "sim_time_s"}


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def short_config():
    config = Config()
    return dataclasses.replace(config, sim=dataclasses.replace(config.sim, settle_time=0.2))


def hold_plan_arrays(scene, duration: float, knots: int = 6) -> dict:
    """plan.npz arrays of a plan that holds the box still: the static-hold reference
    written out with the plan's array names (forces split into lambda_n, lambda_t
    along the contact normal / tangent, torques from eq. 20 at rest)."""
    ref = static_hold_reference(scene, HOLD_ARCLENGTHS, min_normal_force=1.0, duration=duration)
    K = knots
    q0, f_W = ref.q[0], ref.f_W[0]
    n_W = np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]])  # outward normals of the faces
    t_W = np.stack([-n_W[:, 1], n_W[:, 0]], axis=1)
    tau = ImpedanceController(scene.config, Config().controller).compute_actuation(
        np.r_[q0, np.zeros(8)], ref.p_WF[0], np.zeros((4, 2)), f_W
    )
    return {
        "t": np.linspace(0.0, duration, K),
        "x": np.tile(ref.x[0], (K, 1)),
        "xdot": np.zeros((K, 3)),
        "q": np.tile(q0, (K, 1)),
        "qdot": np.zeros((K, 8)),
        "tau": np.tile(tau, (K, 1)),
        "lambda_n": np.tile(-np.sum(f_W * n_W, axis=1), (K, 1)),
        "lambda_t": np.tile(np.sum(f_W * t_W, axis=1), (K, 1)),
        "f_W": np.tile(f_W, (K, 1, 1)),
        "p_W_tip": np.tile(ref.p_WF[0], (K, 1, 1)),
        "p_W_C": np.tile(ref.p_WF[0] - scene.tip_radius * n_W, (K, 1, 1)),
    }


def write_plan_dir(folder, arrays, config: Config):
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(folder / "plan.npz", **arrays)
    (folder / "plan.json").write_text(
        json.dumps({"method": "static-hold", "success": True, "config": config_to_dict(config)})
    )
    return folder


def test_reference_velocities_are_the_fingertip_velocities(scene):
    """v_WF = J(q) qdot agrees with finite differences of forward kinematics."""
    t = np.linspace(0.0, 1.0, 201)
    q0 = np.tile([-0.8, 1.6], 4)
    q = q0 + 0.2 * np.sin(2.0 * t)[:, None] * np.linspace(0.5, 1.0, 8)
    qdot = 0.4 * np.cos(2.0 * t)[:, None] * np.linspace(0.5, 1.0, 8)
    p = np.array([scene.fingertip_positions(qk) for qk in q])
    K = t.size
    arrays = {
        "t": t,
        "x": np.zeros((K, 3)),
        "xdot": np.zeros((K, 3)),
        "q": q,
        "qdot": qdot,
        "tau": np.zeros((K, 8)),
        "lambda_n": np.zeros((K, 4)),
        "lambda_t": np.zeros((K, 4)),
        "f_W": np.zeros((K, 4, 2)),
        "p_W_tip": p,
        "p_W_C": p,
    }
    ref = reference_from_arrays(arrays, scene)
    fd = np.gradient(p, t, axis=0)
    np.testing.assert_allclose(ref.v_WF[1:-1], fd[1:-1], atol=2e-5)


def test_plan_arrays_are_checked(scene):
    arrays = hold_plan_arrays(scene, 1.0)
    check_plan_arrays(arrays)
    check_plan_arrays(arrays, scene.num_fingers)
    with pytest.raises(ValueError, match="'q' has shape"):  # a four-finger plan for a five-finger hand
        check_plan_arrays(arrays, 5)
    with pytest.raises(ValueError, match="lack"):
        check_plan_arrays({k: v for k, v in arrays.items() if k != "f_W"})
    with pytest.raises(ValueError, match="p_W_tip"):
        check_plan_arrays({**arrays, "p_W_tip": arrays["p_W_tip"][:, :3]})
    with pytest.raises(ValueError, match="increasing"):
        check_plan_arrays({**arrays, "t": arrays["t"][::-1]})
    with pytest.raises(ValueError, match="non-finite"):
        check_plan_arrays({**arrays, "x": np.full_like(arrays["x"], np.nan)})


def test_references_hold_their_last_value():
    trajectory = held_trajectory(np.array([0.0, 1.0]), np.array([[0.0, 1.0], [2.0, 3.0]]), hold=0.5)
    np.testing.assert_allclose(trajectory.value(0.5).ravel(), [1.0, 2.0])
    np.testing.assert_allclose(trajectory.value(1.4).ravel(), [2.0, 3.0])
    assert trajectory.end_time() == pytest.approx(1.5)


def test_the_hold_plan_forces_balance_gravity(scene):
    arrays = hold_plan_arrays(scene, 1.0)
    c = scene.config
    f, r = arrays["f_W"][0], arrays["p_W_tip"][0] - 0.01 * np.array([[0, -1], [0, 1], [0, 1], [0, -1]])
    np.testing.assert_allclose(f.sum(axis=0), [0.0, c.box_mass * c.gravity], atol=1e-6)
    np.testing.assert_allclose(np.sum(r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]), 0.0, atol=1e-6)
    assert np.all(arrays["lambda_n"] >= 1.0 - 1e-6)
    assert np.all(np.abs(arrays["lambda_t"]) <= c.mu * arrays["lambda_n"] + 1e-9)


@pytest.mark.slow
def test_run_simulation_result_files_and_gif(scene, short_config, tmp_path):
    arrays = hold_plan_arrays(scene, 0.5)
    reference = reference_from_arrays(arrays, scene)
    gif = tmp_path / "run.gif"
    result = run_simulation(plan=reference, config=short_config, gif_path=gif)
    assert result.t[-1] == pytest.approx(0.7)
    assert result.x.shape == result.x_plan.shape == result.abs_error.shape == (len(result.t), 3)
    assert result.q.shape == (len(result.t), 8)
    np.testing.assert_allclose(result.q[0], arrays["q"][0], atol=1e-9)  # starts in the plan's state
    assert not result.dropped and result.mae_theta < 0.01 and result.mae_y < 0.005
    summary = result.to_json()
    assert SIM_JSON_KEYS <= set(summary)
    json.dumps(summary)
    save_sim(result, tmp_path)
    assert json.loads((tmp_path / "sim.json").read_text()) == summary  # JSON floats round-trip exactly
    loaded = load_sim(tmp_path)
    np.testing.assert_allclose(loaded.abs_error, result.abs_error)
    np.testing.assert_allclose(loaded.f_W, result.f_W)
    assert loaded.to_json() == summary
    from PIL import Image

    with Image.open(gif) as image:
        assert image.format == "GIF" and image.n_frames >= 7


def test_sim_files_round_trip_exactly_and_bad_ones_are_named(tmp_path):
    from trajectotree.config import ConfigError
    from trajectotree.execution.metrics import evaluate
    from trajectotree.results import SIM_ARRAYS, SimLog

    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 11)
    log = SimLog(
        t=t,
        x=rng.normal(size=(11, 3)),
        q=rng.normal(size=(11, 8)),
        x_plan=rng.normal(size=(11, 3)),
        f_W=rng.normal(size=(11, 4, 2)),
        f_W_plan=rng.normal(size=(11, 4, 2)),
        sim_time_s=0.25,
        controller="paper",
        conditions={"sim_mu": 0.5},
    )
    result = evaluate(log, drop_distance=10.0, gravity=9.81)
    save_sim(result, tmp_path)
    loaded = load_sim(tmp_path)
    for name in SIM_ARRAYS:
        np.testing.assert_array_equal(getattr(loaded, name), getattr(result, name))
    assert loaded.to_json() == result.to_json() and loaded.final_error == result.final_error
    (tmp_path / "sim.json").write_text("{}")
    with pytest.raises(ConfigError, match=r"sim.json' is not a valid sim.json \(KeyError: 'mae_x'\)"):
        load_sim(tmp_path)
    (tmp_path / "sim.npz").unlink()
    with pytest.raises(ConfigError, match=r"sim.npz' is missing; a run's folder holds sim.json and sim.npz"):
        load_sim(tmp_path)


def test_simulated_finger_forces_hold_the_box_up_as_planned(scene, short_config):
    """Newton on the held box: the logged finger forces sum to its weight, and each
    finger presses with about the planned (static-grasp) force."""
    reference = reference_from_arrays(hold_plan_arrays(scene, 0.5), scene)
    result = run_simulation(plan=reference, config=short_config)
    assert result.f_W.shape == result.f_W_plan.shape == (len(result.t), 4, 2)
    np.testing.assert_allclose(result.f_W_plan, np.broadcast_to(reference.f_W[0], result.f_W.shape))
    c = scene.config
    late = result.t > 0.2
    np.testing.assert_allclose(
        result.f_W[late].sum(axis=1), np.tile([0.0, c.box_mass * c.gravity], (late.sum(), 1)), atol=0.02
    )
    np.testing.assert_allclose(result.f_W[late], result.f_W_plan[late], atol=0.1)
    # without the controller the fingers let go: no force on the falling box at the end
    open_loop = simulate_reference(reference, short_config, executor=Executor.NONE)
    assert open_loop.dropped and np.all(open_loop.f_W[-1] == 0.0)


def test_simulate_command_writes_sim_json(scene, short_config, tmp_path, capsys):
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), short_config)
    html = tmp_path / "run.html"
    forces = tmp_path / "forces.png"
    assert main(["simulate", str(plan_dir), "--json", "--html", str(html), "--forces", str(forces)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert SIM_JSON_KEYS <= set(printed) and printed["dropped"] is False
    assert json.loads((plan_dir / "sim.json").read_text()) == printed
    text = html.read_text()
    assert "<html" in text.lower() and "animation" in text
    assert len(text) > 500_000  # the viewer's scripts are inlined: the file is self-contained
    assert forces.read_bytes()[:4] == b"\x89PNG"


def test_simulate_command_rejects_bad_plan_dirs(scene, short_config, tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "missing")]) == 2
    assert "not a directory" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["simulate", str(empty)]) == 2
    assert "plan.json" in capsys.readouterr().err
    corrupt = write_plan_dir(tmp_path / "corrupt", hold_plan_arrays(scene, 0.3), short_config)
    (corrupt / "plan.npz").write_bytes(b"not a zip file")
    assert main(["simulate", str(corrupt)]) == 2
    assert "plan.npz" in capsys.readouterr().err
    assert not (corrupt / "sim.json").exists()
    bad_json = write_plan_dir(tmp_path / "bad_json", hold_plan_arrays(scene, 0.3), short_config)
    (bad_json / "plan.json").write_text("{ not json")
    assert main(["simulate", str(bad_json)]) == 2
    assert "plan.json" in capsys.readouterr().err
    wrong_shape = hold_plan_arrays(scene, 0.3)
    wrong_shape["q"] = wrong_shape["q"][:, :6]
    assert main(["simulate", str(write_plan_dir(tmp_path / "shape", wrong_shape, short_config))]) == 2
    assert "'q'" in capsys.readouterr().err
    unsolved = write_plan_dir(tmp_path / "unsolved", {}, short_config)
    assert main(["simulate", str(unsolved)]) == 2
    assert "no trajectory" in capsys.readouterr().err


def test_simulate_command_rejects_a_different_scene(scene, short_config, tmp_path, capsys):
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), short_config)
    assert main(["simulate", str(plan_dir), "--box-size", "0.25", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "scene.box_width = 0.25" in err and "0.2" in err
    assert not (plan_dir / "sim.json").exists()
    assert main(["simulate", str(plan_dir), "--kp", "-1"]) == 2
    assert "controller.impedance.kp" in capsys.readouterr().err
    assert main(["simulate", str(plan_dir), "--forces", str(tmp_path / "forces.gif")]) == 2
    err = capsys.readouterr().err
    assert "forces.gif" in err and ".png" in err
    assert not (plan_dir / "sim.json").exists() and not (tmp_path / "forces.gif").exists()


def test_simulate_command_records_controller_and_conditions(scene, short_config, tmp_path, capsys):
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), short_config)
    assert (
        main(
            [
                "simulate",
                str(plan_dir),
                "--json",
                "--controller",
                "paper",
                "--sim-mu",
                "0.9",
                "--sim-mass",
                "0.06",
                "--push",
                "0.1,-0.05@0.2",
            ]
        )
        == 0
    )
    printed = json.loads(capsys.readouterr().out)
    assert printed["controller"] == "paper"
    assert printed["conditions"] == {
        "sim_mu": 0.9,
        "sim_mass": 0.06,
        "plan_mu": 0.7,
        "plan_mass": 0.05,
        "push": {"force": [0.1, -0.05], "time_s": 0.2, "duration_s": 0.2},
    }
    assert json.loads((plan_dir / "sim.json").read_text())["conditions"] == printed["conditions"]
    assert main(["simulate", str(plan_dir), "--json"]) == 0  # the default: grasp control, the plan's world
    printed = json.loads(capsys.readouterr().out)
    assert printed["controller"] == "grasp" and printed["dropped"] is False
    assert printed["conditions"] == {"sim_mu": 0.7, "sim_mass": 0.05, "plan_mu": 0.7, "plan_mass": 0.05, "push": None}


@pytest.mark.parametrize(
    "options, named",
    [
        (["--sim-mu", "0"], "--sim-mu = 0.0"),
        (["--sim-mu", "-0.3"], "--sim-mu = -0.3"),
        (["--sim-mass", "0"], "--sim-mass = 0.0"),
        (["--sim-mass", "-1"], "--sim-mass = -1.0"),
        (["--push", "0.2,0"], "'0.2,0'"),
        (["--push", "0.2@1"], "'0.2@1'"),
        (["--push", "a,b@1"], "'a,b@1'"),
        (["--push", "0.2,0@-1"], "'0.2,0@-1'"),
        (["--push", "0.2,0@nan"], "'0.2,0@nan'"),
        (["--controller", "pid"], "--controller = 'pid' is not a controller; valid: grasp, paper"),
        (["--rate", "0"], "controller.rate_hz"),
    ],
)
def test_simulate_command_rejects_bad_conditions(scene, short_config, tmp_path, capsys, options, named):
    plan_dir = write_plan_dir(tmp_path / "plan", hold_plan_arrays(scene, 0.3), short_config)
    html = tmp_path / "run.html"
    assert main(["simulate", str(plan_dir), "--html", str(html), *options]) == 2
    err = capsys.readouterr().err
    assert named in err, err
    assert not (plan_dir / "sim.json").exists() and not (plan_dir / "sim.npz").exists() and not html.exists()


def test_run_simulation_conditions_change_the_world_not_the_controller(scene, short_config):
    """A heavier simulated box (model mismatch) sags more than the planned one under the
    same controller; a downward push for 0.2 s moves it down while it acts."""
    from trajectotree.config import ConfigError

    reference = reference_from_arrays(hold_plan_arrays(scene, 0.5), scene)
    nominal = run_simulation(plan=reference, config=short_config)
    heavy = run_simulation(plan=reference, config=short_config, sim_mass=0.1)
    pushed = run_simulation(plan=reference, config=short_config, push="0,-0.3@0.2")
    assert heavy.conditions["sim_mass"] == 0.1 and heavy.conditions["plan_mass"] == 0.05
    late = nominal.t > 0.5

    def sag(r):
        return np.mean(r.x_plan[late, 1] - r.x[late, 1])

    assert sag(heavy) > sag(nominal) + 1e-5
    during = (pushed.t > 0.25) & (pushed.t < 0.4)
    assert np.all(pushed.x[during, 1] < nominal.x[during, 1])
    assert not (nominal.dropped or heavy.dropped or pushed.dropped)
    with pytest.raises(ConfigError, match="sim_mu = 0"):
        run_simulation(plan=reference, config=short_config, sim_mu=0.0)
    with pytest.raises(ConfigError, match="'x@1'"):
        run_simulation(plan=reference, config=short_config, push="x@1")


@pytest.mark.slow
def test_a_trajectotree_plan_executes_end_to_end(tmp_path):
    """Plan a 0.3 rad turn in 2 segments (a finger switch each) with TrajectoTree, execute
    it under the default grasp controller, save and reload."""
    from trajectotree.planning.planners import plan

    config = Config()
    config = dataclasses.replace(config, search=dataclasses.replace(config.search, num_nodes=3))
    result = plan(scene=build_scene(config.scene), goal=0.3, method="trajectotree", config=config)
    assert result.success, result.status
    sim = run_simulation(plan=result, config=config)
    assert sim.controller == "grasp"
    plan_end = result.trajectory.t[-1]
    assert sim.t[-1] == pytest.approx(plan_end + config.sim.settle_time)
    assert not sim.dropped
    assert sim.mae_theta < 0.05 and sim.mae_x < 3e-3 and sim.mae_y < 3e-3
    # fingers were switched: each one of them let go of the box for a while
    switched = [i for i in range(4) if np.any(np.all(sim.f_W[:, i] == 0.0, axis=1) & (sim.t < plan_end))]
    assert len(switched) >= 1
    # the box turned with the plan: near the planned pose when the plan ends
    k = np.searchsorted(sim.t, plan_end)
    assert sim.x[k, 2] > 0.2 and abs(sim.x[k, 2] - sim.x_plan[k, 2]) < 0.1
    save_sim(sim, tmp_path)
    assert load_sim(tmp_path).to_json() == sim.to_json()
