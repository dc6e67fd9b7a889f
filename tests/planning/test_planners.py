"""End-to-end planning on small goals: the physics of the saved plan checked from
plan.npz alone (Newton-Euler under the trapezoidal rule with forces at p_W_C,
friction cones at mu_plan, penetration, contact points, no force from a fingertip
off the box, the lifted switching finger), the files, the paper's config, and bad input."""

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from trajectotree.cli import main
from trajectotree.config import (
    CitoConfig,
    Config,
    ConfigError,
    SceneConfig,
    SearchConfig,
    config_to_dict,
    load_config,
    mu_plan,
    save_config,
)
from trajectotree.geometry import ConvexPolygon, box_to_world, world_to_box
from trajectotree.io import load_plan, save_plan
from trajectotree.planning.planners import plan
from trajectotree.scene.plant import build_scene

# 2 segments, 25 knots: seconds per solve; the paper's order of the search's children, whose plans of +-0.3 both
# switch a finger (the push order turns +0.3 with all four holding)
CONFIG = Config(search=SearchConfig(num_nodes=3, push_capacity=0.0))


@pytest.fixture(scope="module")
def scene():
    return build_scene(CONFIG.scene)


@pytest.fixture(scope="module")
def plans(scene, tmp_path_factory):
    """Each (method, goal) planned once, saved and loaded back from its files."""
    out = {}
    for method, goal in (("trajectotree", 0.3), ("trajectotree", -0.3), ("cito-warm", 0.3), ("cito", 0.3)):
        folder = tmp_path_factory.mktemp(f"{method}_{goal:+.1f}")
        result = plan(scene=scene, goal=goal, method=method, config=CONFIG)
        save_plan(result, folder)
        out[method, goal] = (result, folder)
    return out


def npz(folder):
    with np.load(folder / "plan.npz") as data:
        return {k: data[k] for k in data.files}


def check_newton_euler(a, scene_config: SceneConfig, tol=1e-5, moment_tol=1e-4):
    """m (v_{k+1} - v_k)/dt = (F_k + F_{k+1})/2 + m g and the same for the rotation, with
    F the sum of the finger forces f_W and the moments of f_W about the box centre,
    applied at the saved points p_W_C on the box surface. The moments hold to moment_tol
    (N m): the program applies a pinned finger's force at its fingertip, which may sit its
    contact-point slack (~1e-5 m) away from the planned point p_W_C."""
    m, w, h = scene_config.box_mass, scene_config.box_width, scene_config.box_height
    inertia = m * (w * w + h * h) / 12
    t, x, xd, f = a["t"], a["x"], a["xdot"], a["f_W"]
    dt = np.diff(t)[:, None]
    np.testing.assert_allclose(np.diff(x, axis=0), dt / 2 * (xd[1:] + xd[:-1]), atol=1e-7)
    box = ConvexPolygon.box(w, h)
    assert max(abs(box.signed_distance(world_to_box(xk, p))) for xk, ps in zip(x, a["p_W_C"]) for p in ps) < 1e-12
    arm = a["p_W_C"] - x[:, None, :2]
    moment = np.sum(arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0], axis=1)
    wrench = np.concatenate([f.sum(1) + m * np.array([0.0, -scene_config.gravity]), moment[:, None]], axis=1)
    inertia_diag = np.array([m, m, inertia])
    residual = inertia_diag * np.diff(xd, axis=0) / dt - 0.5 * (wrench[1:] + wrench[:-1])
    assert np.abs(residual[:, :2]).max() < tol
    assert np.abs(residual[:, 2]).max() < moment_tol
    # The force is the contact-frame force in W: |f_W| = |(lambda_n, lambda_t)|.
    np.testing.assert_allclose(np.linalg.norm(f, axis=2), np.hypot(a["lambda_n"], a["lambda_t"]), atol=1e-9)


def tip_distances(a, scene_config, radius):
    """(K, 4) exact distance of each fingertip sphere to the box (negative: penetration)."""
    box = scene_config.shape
    return np.array(
        [[box.signed_distance(world_to_box(x, p)) - radius for p in tips] for x, tips in zip(a["x"], a["p_W_tip"])]
    )


@pytest.mark.slow
@pytest.mark.parametrize("key", [("trajectotree", 0.3), ("trajectotree", -0.3)])
def test_plan_is_physical(plans, scene, key):
    result, folder = plans[key]
    assert result.success, result.status
    a = npz(folder)
    c, r = scene.config, scene.tip_radius
    check_newton_euler(a, c)
    ln, lt = a["lambda_n"], a["lambda_t"]
    mu = mu_plan(CONFIG.scene, CONFIG.search)
    assert mu == pytest.approx(0.7 * c.mu)  # the default safety
    assert np.all(ln >= -1e-7) and np.all(np.abs(lt) <= mu * ln + 1e-7)  # cones at mu_plan
    pressing = ln > 0.05
    assert (np.abs(lt[pressing]) / ln[pressing]).max() > 0.9 * mu  # ... and they bind
    dist = tip_distances(a, c, r)
    assert dist.min() > -1e-3  # no tip 1 mm inside
    away = dist > 1e-4  # no force at a distance
    assert np.all(np.linalg.norm(a["f_W"], axis=2)[away] <= 0.01), np.linalg.norm(a["f_W"], axis=2)[away].max()
    assert result.physics_check.passed and result.physics_check.mu == pytest.approx(mu)
    assert abs(a["x"][-1, 2] - key[1]) < np.deg2rad(5)  # reaches the goal


@pytest.mark.slow
@pytest.mark.parametrize("goal", [0.3, -0.3])
def test_trajectotree_keeps_fixed_fingers_on_their_planned_contacts(plans, scene, goal):
    result, folder = plans["trajectotree", goal]
    a = npz(folder)
    nodes = result.contact_plan.nodes
    M = result.config.cito.knots_per_segment
    r = scene.tip_radius
    for s in range(len(nodes) - 1):
        moving = nodes[s + 1].switching_finger
        for k in range(s * M, (s + 1) * M + 1):
            for i in range(4):
                node = nodes[s + 1] if (k == (s + 1) * M or i != moving) else nodes[s]
                if i == moving and s * M < k < (s + 1) * M:
                    continue  # free in between
                target = box_to_world(a["x"][k], node.p_BC[i] + r * node.n_B[i])
                assert np.linalg.norm(a["p_W_tip"][k, i] - target) < 2e-3, (s, k, i)
    assert result.violations["contact_point"] < 2e-3
    assert result.violations["penetration"] < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("goal", [0.3, -0.3])
def test_the_switching_finger_lifts_off_and_carries_no_force(plans, scene, goal):
    result, folder = plans["trajectotree", goal]
    a, config = npz(folder), result.config
    h, M = config.cito.switch_clearance, config.cito.knots_per_segment
    assert h > 0  # the default lifts it
    gaps = tip_distances(a, config.scene, scene.tip_radius)
    switches = [
        (s, node.switching_finger)
        for s, node in enumerate(result.contact_plan.nodes[1:])
        if node.switching_finger is not None
    ]
    assert switches
    j = np.arange(1, M)
    for s, finger in switches:
        mid = gaps[s * M + j, finger]
        # The smooth distance the program uses over-estimates the exact one near corners by <= log(2)/1000 m.
        assert np.all(mid >= h * np.sin(np.pi * j / M) - 1e-3), (s, mid)
        assert mid.max() >= 0.8 * h  # clears the face
        # ... and, held off the box, it does not push it (no force across the gap)
        assert np.abs(a["f_W"][s * M + j, finger]).max() <= 1e-8, (s, a["f_W"][s * M + j, finger])
        assert np.all(a["lambda_n"][s * M + j, finger] <= 1e-8)


@pytest.mark.slow
def test_saved_plan_round_trips_and_matches_design(plans):
    result, folder = plans["trajectotree", 0.3]
    data = json.loads((folder / "plan.json").read_text())
    for key in (
        "method",
        "goal",
        "success",
        "status",
        "search_time_s",
        "solve_time_s",
        "total_time_s",
        "cost",
        "iterations",
        "contact_sequence",
        "violations",
        "config",
    ):
        assert key in data
    assert set(data["violations"]) == {"dynamics", "friction_cone", "complementarity", "contact_point", "penetration"}
    node = data["contact_sequence"][1]
    assert set(node) >= {"object_pose", "q", "switching_finger", "contacts"}
    assert set(node["contacts"][0]) >= {"arclength", "p_B", "n_B"}
    a = npz(folder)
    K = 2 * CONFIG.cito.knots_per_segment + 1
    shapes = {
        "t": (K,),
        "x": (K, 3),
        "xdot": (K, 3),
        "q": (K, 8),
        "qdot": (K, 8),
        "tau": (K, 8),
        "lambda_n": (K, 4),
        "lambda_t": (K, 4),
        "f_W": (K, 4, 2),
        "p_W_tip": (K, 4, 2),
        "p_W_C": (K, 4, 2),
    }
    assert {k: v.shape for k, v in a.items()} == shapes
    assert data["physics_check"]["passed"] is True and data["physics_check"]["force_tol_N"] == 0.01
    loaded = load_plan(folder)
    assert loaded.config == result.config and loaded.status == result.status
    assert loaded.physics_check == result.physics_check and loaded.converged is result.converged is True
    np.testing.assert_array_equal(loaded.trajectory.f_W, result.trajectory.f_W)
    assert loaded.contact_plan.nodes[1].switching_finger == result.contact_plan.nodes[1].switching_finger
    assert loaded.contact_plan.mu_plan == result.contact_plan.mu_plan == pytest.approx(0.49)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["cito-warm", "cito"])
def test_baselines_are_physical_or_say_why_not(plans, scene, method):
    """The general CITO's relaxed complementarity (eqs. 5-6) lets a fingertip push from a
    distance (on goal 0.3, cito-warm 0.06 N from 1.1 mm, cito 0.12 N from 2.3 mm): such a
    converged plan is a failure with the reason, found again here from plan.npz alone."""
    result, folder = plans[method, 0.3]
    a, c = npz(folder), scene.config
    assert result.status.split(",")[0] in ("Success", "Stop at acceptable point"), result.status  # converged
    check_newton_euler(a, c, moment_tol=1e-3)  # forces off the box act 1-2 mm from p_W_C
    assert np.all(np.abs(a["lambda_t"]) <= mu_plan(CONFIG.scene, CONFIG.search) * a["lambda_n"] + 1e-7)
    pushing = (tip_distances(a, c, scene.tip_radius) > 1e-4) & (np.linalg.norm(a["f_W"], axis=2) > 0.01)
    assert result.converged and result.success == result.physics_check.passed == (not pushing.any())
    if pushing.any():
        assert "physics check failed" in result.status and "pushes the box" in result.status


@pytest.mark.slow
def test_cito_baseline_from_static_guess_and_times(plans):
    result, _ = plans["cito", 0.3]
    assert result.search_time_s == 0.0 and len(result.contact_plan.nodes) == 1
    assert result.total_time_s == pytest.approx(result.build_time_s + result.solve_time_s)
    assert result.violations["dynamics"] < 1e-5


@pytest.mark.slow
def test_plan_files_without_p_W_C_are_refused_by_name(plans, tmp_path):
    _, folder = plans["trajectotree", 0.3]
    (tmp_path / "plan.json").write_text((folder / "plan.json").read_text())
    np.savez(tmp_path / "plan.npz", **{k: v for k, v in npz(folder).items() if k != "p_W_C"})
    with pytest.raises(ConfigError, match="p_W_C"):
        load_plan(tmp_path)


def test_paper_config_loads_with_the_papers_formulation():
    config = load_config(Path(__file__).parents[2] / "configs" / "paper.yaml")
    assert config.search.friction_safety == 1.0 and config.cito.switch_clearance == 0.0
    assert config.cito.formulation == "joint"
    assert mu_plan(config.scene, config.search) == config.scene.mu
    default = Config()
    assert dataclasses.replace(config, search=default.search, cito=default.cito) == default  # nothing else differs
    assert not config.search.rolled_stances and config.search.grid_refinements == 0
    assert config.search.max_stance_force == 0.0 and config.search.push_capacity == 0.0
    assert (
        dataclasses.replace(
            config.search,
            friction_safety=default.search.friction_safety,
            rolled_stances=default.search.rolled_stances,
            grid_refinements=default.search.grid_refinements,
            max_stance_force=default.search.max_stance_force,
            push_capacity=default.search.push_capacity,
        )
        == default.search
    )
    assert not config.cito.link_rows  # the paper models no links
    assert (
        dataclasses.replace(
            config.cito,
            switch_clearance=default.cito.switch_clearance,
            formulation=default.cito.formulation,
            link_rows=default.cito.link_rows,
        )
        == default.cito
    )


def test_load_plan_rejects_missing_and_corrupt_folders(tmp_path):
    with pytest.raises(ConfigError, match="not a directory"):
        load_plan(tmp_path / "nothing")
    with pytest.raises(ConfigError, match="plan.json' is missing"):
        load_plan(tmp_path)
    (tmp_path / "plan.json").write_text("{not json")
    (tmp_path / "plan.npz").write_bytes(b"junk")
    with pytest.raises(ConfigError, match="plan.json"):
        load_plan(tmp_path)
    config = config_to_dict(CONFIG)
    config["scene"]["mu"] = -1.0
    (tmp_path / "plan.json").write_text(json.dumps({"config": config}))
    with pytest.raises(ConfigError, match=r"plan.json' holds an invalid config: scene.mu = -1.0 is out of range"):
        load_plan(tmp_path)
    (tmp_path / "plan.json").write_text(json.dumps({"config": config_to_dict(CONFIG)}))
    (tmp_path / "plan.npz").write_bytes(b"PK\x03\x04 a truncated zip")
    with pytest.raises(ConfigError, match=r"plan.npz' is not a valid plan.npz \(BadZipFile"):
        load_plan(tmp_path)
    np.savez(tmp_path / "plan.npz")  # nothing solved: plan.json must then hold the rest of the report
    with pytest.raises(ConfigError, match=r"plan.json' is not a valid plan.json \(KeyError: 'goal'\)"):
        load_plan(tmp_path)


def test_bad_input_raises_config_errors(scene):
    with pytest.raises(ConfigError, match="goal"):
        plan(scene=scene, goal=float("nan"), method="trajectotree", config=CONFIG)
    with pytest.raises(ConfigError, match="goal"):
        plan(scene=scene, goal=70.0, method="trajectotree", config=CONFIG)  # beyond ten turns
    with pytest.raises(ConfigError, match="outside the hand's workspace"):
        plan(scene=scene, goal=(0.25, 0.0, 0.3), method="trajectotree", config=CONFIG)
    with pytest.raises(ConfigError, match="method"):
        plan(scene=scene, goal=0.3, method="rrt", config=CONFIG)
    other = dataclasses.replace(CONFIG, scene=SceneConfig(box_width=0.16))
    with pytest.raises(ConfigError, match="SceneConfig"):
        plan(scene=scene, goal=0.3, method="cito", config=other)


def test_contact_plan_not_matching_the_scene_is_rejected(scene):
    from trajectotree.planning.planners import initial_grasp_plan

    flat = build_scene(SceneConfig(box_height=0.08))
    config = dataclasses.replace(CONFIG, scene=flat.config)
    grasp = initial_grasp_plan(scene, 0.3, CONFIG)  # contacts on the 0.10 m high box
    two = dataclasses.replace(grasp, nodes=grasp.nodes * 2)
    with pytest.raises(ConfigError, match="off the boundary"):
        plan(scene=flat, goal=0.3, method="trajectotree", config=config, contact_plan=two)


def run_cli(capsys, *args) -> SimpleNamespace:
    """`trajectotree plan ARGS` through the CLI's main in this process: its exit code, stdout and stderr."""
    code = main(["plan", *args])
    printed = capsys.readouterr()
    return SimpleNamespace(returncode=code, stdout=printed.out, stderr=printed.err)


@pytest.mark.slow
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys):
    for args in (
        ["--goal", "nan"],
        ["--goal", "0.3", "--method", "chomp"],
        ["--goal", "70"],
        ["--goal-pose", "1", "0", "0"],
    ):
        proc = run_cli(capsys, *args, "--out", str(tmp_path / "out"))
        assert proc.returncode == 2, proc.stderr
        assert "error" in proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_cli_non_converged_plan_is_written_with_status(tmp_path, capsys):
    config = dataclasses.replace(CONFIG, cito=CitoConfig(max_iter=3, formulation="joint"))  # one program
    save_config(config, tmp_path / "c.yaml")
    proc = run_cli(
        capsys, "--goal", "0.2", "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "p"), "--json"
    )
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["success"] is False and "iteration" in data["status"].lower() and data["iterations"] == 3
    assert json.loads((tmp_path / "p" / "plan.json").read_text())["status"] == data["status"]
    assert npz(tmp_path / "p")["x"].shape == (25, 3)


@pytest.mark.slow
def test_a_translated_goal_plans_to_its_pose_and_is_physical(scene):
    result = plan(scene=scene, goal=(0.01, -0.005, 0.3), method="trajectotree", config=CONFIG)
    assert result.success, result.status
    a = result.trajectory.arrays()
    np.testing.assert_allclose(a["x"][-1], (0.01, -0.005, 0.3), atol=1e-9)  # the goal node's pose
    assert np.ptp(a["x"][:, 0]) > 0.009  # the object moves, not only turns
    check_newton_euler(a, scene.config)
    assert result.config.goal.position == (0.01, -0.005) and result.contact_plan.goal_position == (0.01, -0.005)


@pytest.mark.slow
def test_a_full_turn_plans_to_the_goal_and_is_physical():
    # a full turn and 0.2 rad more with the default settings: 22 segments (config.segments_for), solved in
    # parallel. 2 pi itself has no search plan within the 30 s budget since the fingers are kept apart
    # (two initial grasps searched); 2 pi + 0.2 plans in about 1,200 expansions.
    full_turn = 2 * np.pi + 0.2
    result = plan(goal=full_turn, method="trajectotree")
    assert result.success, result.status
    assert len(result.contact_plan.nodes) == 23 and result.config.search.num_nodes == 23
    a = result.trajectory.arrays()
    assert a["x"][-1, 2] == pytest.approx(full_turn, abs=1e-9)
    nodes = a["x"][:: result.config.cito.knots_per_segment]  # the segments' end knots: the search's node poses
    np.testing.assert_allclose(nodes, result.contact_plan.object_path, atol=1e-9)
    check_newton_euler(a, result.config.scene)
    assert result.physics_check.passed
