"""The contact-sequence planner: every node of a found plan is checked independently
(form closure by a fresh LP, reachability by the plant's kinematics, collisions by
SceneGraph), on positive and negative goals and a non-default box and friction."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from test_reach import signed_distances

from trajectotree.cli import main
from trajectotree.config import Config, ConfigError, GoalPose, SceneConfig, SearchConfig, segments_for
from trajectotree.contact_plan import ContactPlan
from trajectotree.geometry import ConvexPolygon, box_to_world, rotation_2d
from trajectotree.planning.planners import initial_grasp_plan
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.grasp import FormClosure
from trajectotree.search.initial_grasp import initial_grasp_candidates
from trajectotree.search.reach import Reachability
from trajectotree.search.tree import _Node, _Search, choose_initial_grasp, find_contact_plan, grid_levels

OLD_DEFAULT_GRASP = (0.54, 0.12, 0.36, 0.48)  # its stance of fingers 1, 2, 3 needs mu 0.67


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def small_slippery_scene():
    return build_scene(SceneConfig(box_width=0.16, box_height=0.08, mu=0.5))


def check_plan(scene, plan, config: SearchConfig):
    c = scene.config
    boundary = c.shape
    mu_plan = config.friction_safety * c.mu
    closure = FormClosure(boundary, mu_plan, config.min_closure_margin)
    assert plan.success, plan.reason
    assert plan.mu_plan == pytest.approx(mu_plan)
    goal = GoalPose(theta=plan.goal, position=plan.goal_position)
    N = segments_for(config, c.initial_pose, goal) + 1
    assert len(plan.nodes) == N
    # object path: linear interpolation from the initial pose to the goal pose
    np.testing.assert_allclose(plan.object_path[0], c.initial_pose)
    np.testing.assert_allclose(plan.object_path[-1], goal.pose(c.initial_pose), atol=1e-12)
    np.testing.assert_allclose(
        np.diff(plan.object_path, axis=0),
        np.array([np.subtract(goal.pose(c.initial_pose), c.initial_pose) / (N - 1)] * (N - 1)),
        atol=1e-12,
    )
    # node 0 is the user's initial grasp, or one of the chooser's candidates
    if config.initial_arclengths is not None:
        np.testing.assert_allclose(
            plan.nodes[0].arclengths, np.mod(config.initial_arclengths, boundary.perimeter), atol=1e-9
        )
    else:
        # the candidates of the grid the plan was found on (the configured one, else a refined one)
        candidates = [
            c.arclengths for level in grid_levels(config) for c in initial_grasp_candidates(scene, level).candidates
        ]
        assert tuple(plan.nodes[0].arclengths) in candidates
    assert plan.nodes[0].switching_finger is None and plan.nodes[0].stance_required_mu is None
    for n, node in enumerate(plan.nodes):
        result = closure.check(node.arclengths)  # a fresh LP at mu_plan
        assert result.in_closure and result.margin > config.min_closure_margin
        assert node.closure_margin == pytest.approx(result.margin, abs=1e-6)
        assert node.required_mu == pytest.approx(closure.required_mu(node.arclengths)) and node.required_mu < mu_plan
        for i in range(NUM_FINGERS):
            p, normal = boundary.point(node.arclengths[i])
            np.testing.assert_allclose(node.p_BC[i], p, atol=1e-12)
            np.testing.assert_allclose(node.n_B[i], normal, atol=1e-12)
            assert boundary.signed_distance(node.p_BC[i]) == pytest.approx(0.0, abs=1e-12)
            assert boundary.corner_distance(node.arclengths[i]) >= c.corner_margin - 1e-12
        # the IK joint angles put every fingertip sphere on its contact, within joint limits
        p_WF = scene.fingertip_positions(node.q)
        for i, f in enumerate(scene.fingers):
            n_W = rotation_2d(node.object_pose[2]) @ node.n_B[i]
            target = box_to_world(node.object_pose, node.p_BC[i]) + scene.tip_radius * n_W
            np.testing.assert_allclose(p_WF[i], target, atol=1e-5)
            q = node.q[2 * i : 2 * i + 2]
            assert np.all(q >= f.q_lower - 1e-7) and np.all(q <= f.q_upper + 1e-7)
        assert np.all(signed_distances(scene, node.object_pose, node.q) > -1e-6)  # no link enters the box
        if n == 0:
            continue
        before = plan.nodes[n - 1]
        changed = [i for i in range(NUM_FINGERS) if abs(node.arclengths[i] - before.arclengths[i]) > 1e-9]
        assert len(changed) <= 1  # at least three contacts shared
        assert changed == ([] if node.switching_finger is None else [node.switching_finger])
        if node.switching_finger is not None:  # the moving finger was free: the other three held the box
            others = [s for i, s in enumerate(before.arclengths) if i != node.switching_finger]
            assert closure.check(others).in_closure  # at mu_plan, by the LP
            assert node.stance_required_mu == pytest.approx(closure.required_mu(others))
            assert node.stance_required_mu < mu_plan
        else:
            assert node.stance_required_mu is None


@pytest.mark.parametrize("goal", [np.pi, -np.pi, 1.1, -2.3])
def test_plans_satisfy_every_node_condition(scene, goal):
    config = SearchConfig()
    plan = find_contact_plan(scene, goal, config)
    check_plan(scene, plan, config)
    s = plan.stats
    assert s.expanded >= 10 and s.lp_calls > 0 and s.ik_calls >= 4 * 10  # the paper's N = 10 for |goal| <= pi


@pytest.mark.parametrize("goal", [1.5, -1.0])
def test_non_default_box_and_friction(small_slippery_scene, goal):
    config = SearchConfig()
    plan = find_contact_plan(small_slippery_scene, goal, config)
    check_plan(small_slippery_scene, plan, config)


@pytest.mark.fresh
def test_initial_grasp_candidates(scene):
    config = SearchConfig()
    table = initial_grasp_candidates(scene, config)
    mu_plan = config.friction_safety * scene.config.mu
    boundary, reach = ConvexPolygon.box(0.20, 0.10), Reachability(scene)
    closure = FormClosure(boundary, mu_plan, 1e-9)
    assert table.mu_plan == pytest.approx(mu_plan) and table.refusal is None
    assert 100 < len(table.candidates) <= table.assignments
    worst = [c.worst_stance_mu for c in table.candidates]
    assert np.all(np.diff(np.round(worst, 4)) >= 0)  # ranked by the worst stance that may let go
    for c in table.candidates[:40]:
        for i, s in enumerate(c.arclengths):
            assert boundary.corner_distance(s) >= scene.config.corner_margin
            assert reach.solve(scene.config.initial_pose, i, s).reachable  # Drake IK, no link in the box
            others = [v for j, v in enumerate(c.arclengths) if j != i]
            assert c.stance_required_mu[i] == pytest.approx(closure.required_mu(others), abs=2e-5)  # ranked to ~1e-5
            assert closure.is_free(c.arclengths, i) == (c.stance_required_mu[i] < mu_plan)
        assert closure.check(c.arclengths).in_closure
        tips = [reach.contact(s)[0] + reach.tip_radius * reach.contact(s)[1] for s in c.arclengths]
        assert min(np.linalg.norm(a - b) for k, a in enumerate(tips) for b in tips[k + 1 :]) >= 2 * reach.tip_radius
    # the old fixed grasp is a candidate, but finger 0 may not let go at mu_plan 0.49
    old = next(c for c in table.candidates if np.allclose(c.arclengths, OLD_DEFAULT_GRASP))
    assert old.stance_required_mu[0] == pytest.approx(0.6698, abs=1e-4) and old.free_fingers == 2


def test_search_refuses_a_stance_below_the_margin(scene):
    # Fingers 1, 2, 3 of the old default grasp need mu 0.67: finger 0 may let go at
    # mu_plan 0.7 (friction_safety 1, the paper) but not at 0.49 (the default 0.7).
    def children_moving(safety):
        search = _Search(scene, -1.0, SearchConfig(initial_arclengths=OLD_DEFAULT_GRASP, friction_safety=safety))
        search.plan_switch_bounds([{s} for s in OLD_DEFAULT_GRASP])
        return {child.switching_finger for *_, child in search.neighbors(_Node(0, OLD_DEFAULT_GRASP, None, None))}

    assert 0 in children_moving(1.0) and 0 not in children_moving(0.7)
    paper = find_contact_plan(scene, -1.0, SearchConfig(initial_arclengths=OLD_DEFAULT_GRASP, friction_safety=1.0))
    assert paper.success and paper.nodes[1].switching_finger == 0
    assert paper.nodes[1].stance_required_mu == pytest.approx(0.6698, abs=1e-4)
    refused = find_contact_plan(scene, -1.0, SearchConfig(initial_arclengths=OLD_DEFAULT_GRASP))
    assert not refused.success and "finger 0 must move (out of reach) but is held: stance of fingers (1, 2, 3)" in (
        refused.reason
    )
    held = Refusal(RefusalKind.STUCK_FINGER_HELD, fingers=(0,), stance=(1, 2, 3), mu_plan=refused.mu_plan)
    on_the_grid = refused.refusal.grids[0][1]  # the coarse grid's NoPlan (the fine grid's follows)
    assert refused.refusal.kind is RefusalKind.ON_GRIDS and held in dict(on_the_grid.refused)
    # the chooser's grasps find the goal with the margin
    check_plan(scene, find_contact_plan(scene, -1.0, SearchConfig()), SearchConfig())


def test_cito_uses_the_choosers_first_choice(scene):
    for goal in (-2.5, 0.4):
        chosen, refusal = choose_initial_grasp(scene, goal, SearchConfig())
        assert refusal is None and chosen in [
            c.arclengths for c in initial_grasp_candidates(scene, SearchConfig()).candidates
        ]
        node = initial_grasp_plan(scene, goal, Config()).nodes[0]
        np.testing.assert_allclose(node.arclengths, chosen)
        assert node.required_mu < 0.49 and node.closure_margin > 1e-3
    given = SearchConfig(initial_arclengths=(0.54, 0.14, 0.32, 0.5))
    assert choose_initial_grasp(scene, 0.8, given) == ((0.54, 0.14, 0.32, 0.5), None)


def test_plan_json_keeps_required_friction(scene):
    plan = find_contact_plan(scene, 0.7, SearchConfig())
    data = json.loads(json.dumps(plan.to_json()))
    again = ContactPlan.from_json(data)
    assert again.mu_plan == pytest.approx(plan.mu_plan)
    for a, b in zip(again.nodes, plan.nodes):
        assert a.required_mu == pytest.approx(b.required_mu) and a.stance_required_mu == b.stance_required_mu
    for node in data["contact_sequence"]:  # a file written before these keys existed still loads
        del node["required_mu"], node["stance_required_mu"]
    del data["mu_plan"]
    old = ContactPlan.from_json(data)
    assert np.isnan(old.nodes[1].required_mu) and old.nodes[1].stance_required_mu is None and np.isnan(old.mu_plan)


def test_custom_initial_grasp_and_segments(scene):
    config = SearchConfig(num_nodes=5, initial_arclengths=(0.54, 0.14, 0.32, 0.5))
    check_plan(scene, find_contact_plan(scene, 0.8, config), config)


def test_failures_are_results_with_a_reason(scene):
    # all four contacts on the bottom face: not in form closure
    plan = find_contact_plan(scene, 0.5, SearchConfig(initial_arclengths=(0.43, 0.47, 0.51, 0.55), grid_refinements=0))
    assert not plan.success and plan.nodes == ()
    assert plan.refusal.kind is RefusalKind.INITIAL_GRASP and plan.refusal.cause.kind is RefusalKind.NOT_IN_CLOSURE
    assert plan.reason.startswith("initial grasp infeasible: not in frictional form closure at mu_plan 0.49")
    # a half turn in 3 nodes needs more contact switches than 2 steps allow
    plan = find_contact_plan(scene, np.pi, SearchConfig(num_nodes=3, grid_refinements=0))
    assert not plan.success and "skipped by cheap checks" in plan.reason and plan.stats.initial_grasps_searched == 0
    assert plan.refusal.kind is RefusalKind.NO_PLAN and plan.refusal.searched == 0
    given = SearchConfig(num_nodes=3, initial_arclengths=(0.54, 0.14, 0.32, 0.5), grid_refinements=0)
    plan = find_contact_plan(scene, np.pi, given)
    assert not plan.success and plan.refusal.kind is RefusalKind.TOO_MANY_SWITCHES and plan.refusal.limit == 2
    assert "contact switches" in plan.reason and "more than the 2 steps of 3 nodes" in plan.reason
    # a tiny node budget
    plan = find_contact_plan(scene, np.pi, SearchConfig(max_expansions=3))
    assert not plan.success and "budget" in plan.reason and plan.stats.expanded == 3
    assert plan.refusal.last_searched.refusal == Refusal(RefusalKind.NODE_BUDGET, count=3)
    # the refusal survives plan.json: the same value, not only its text
    again = ContactPlan.from_json(json.loads(json.dumps(plan.to_json())))
    assert again.refusal == plan.refusal and again.reason == plan.reason
    with pytest.raises(ConfigError):
        find_contact_plan(scene, float("nan"), SearchConfig())


def run_cli(capsys, *args) -> SimpleNamespace:
    """`trajectotree search ARGS` through the CLI's main in this process: its exit code, stdout and stderr."""
    code = main(["search", *args])
    printed = capsys.readouterr()
    return SimpleNamespace(returncode=code, stdout=printed.out, stderr=printed.err)


@pytest.mark.slow
def test_cli_json_and_figure(tmp_path, capsys):
    figure = tmp_path / "plan.png"
    argv = ["--goal", "-1.2", "--json", "--figure", str(figure), "--box-size", "0.16", "0.08", "--mu", "0.5"]
    out = run_cli(capsys, *argv)
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["success"] and len(data["contact_sequence"]) == 10
    node = data["contact_sequence"][3]
    assert set(node) >= {"object_pose", "q", "switching_finger", "contacts"}
    assert (
        len(node["q"]) == 8 and len(node["contacts"]) == 4 and set(node["contacts"][0]) >= {"arclength", "p_B", "n_B"}
    )
    assert figure.stat().st_size > 10_000
    # a failed search still exits 0, with the reason
    out = run_cli(capsys, "--goal", "3.0", "--segments", "2", "--json")
    assert out.returncode == 0 and json.loads(out.stdout)["success"] is False
    # invalid input exits 2 and names the valid range
    out = run_cli(capsys, "--goal", "64")
    assert out.returncode == 2 and "[-20 pi, 20 pi]" in out.stderr
