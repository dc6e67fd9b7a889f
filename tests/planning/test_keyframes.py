"""The keyframes formulation (trajectotree.planning.keyframes) on a real 2-segment plan (goal 0.3 rad,
3 nodes, 25 knots): the stitched plan is continuous at every node and physical, its
segments solved in parallel equal the serial solve bit for bit, a failing segment is
retried and plan.json says so, and bad input is refused."""

import dataclasses
import json

import numpy as np
import pytest

from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program
from trajectotree.cito.transition import piece_spec
from trajectotree.cli import main
from trajectotree.config import CitoConfig, Config, ConfigError, SearchConfig, mu_plan
from trajectotree.io import load_plan, save_plan
from trajectotree.planning.keyframes import _neighbour_ranges, stitch
from trajectotree.planning.physics import ObjectModel, check_physics
from trajectotree.planning.planners import plan
from trajectotree.planning.segment_pool import local_pool
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

# 2 segments of 12 knots; the paper's order of the search's children, whose plan's first segment needs the link retry
CONFIG = Config(search=SearchConfig(num_nodes=3, push_capacity=0.0))
GOAL = 0.3


@pytest.fixture(scope="module")
def scene():
    return build_scene(CONFIG.scene)


@pytest.fixture(scope="module")
def contact_plan(scene):
    result = find_contact_plan(scene, GOAL, CONFIG.search)
    assert result.success, result.reason
    return result


@pytest.fixture(scope="module")
def serial(scene, contact_plan):
    return plan(
        scene=scene, goal=GOAL, method="trajectotree", config=CONFIG, contact_plan=contact_plan, segment_workers=1
    )


def test_keyframes_is_the_default_and_joint_the_papers():
    assert CitoConfig().formulation == "keyframes"
    assert CitoConfig(formulation="joint").formulation == "joint"


def test_piece_spec_fixes_both_ends_at_the_nodes(scene, contact_plan):
    spec = piece_spec(contact_plan, 1, 2, radius=scene.tip_radius, config=CONFIG.cito)
    first, last = contact_plan.nodes[1], contact_plan.nodes[2]
    assert spec.num_knots == CONFIG.cito.knots_per_segment + 1
    np.testing.assert_array_equal(spec.x0, first.object_pose)
    np.testing.assert_array_equal(spec.q_end, last.q)
    assert spec.static_knots == (0, spec.num_knots - 1)
    program = build_program(
        CONFIG.cito, spec, BodyParams(scene, CONFIG.cito.sdf_sharpness, mu=mu_plan(CONFIG.scene, CONFIG.search))
    )
    v, prog = program.variables, program.prog
    fixed = {}
    for binding in prog.bounding_box_constraints():
        c = binding.evaluator()
        for var, lo, hi in zip(binding.variables(), c.lower_bound(), c.upper_bound()):
            if lo == hi:
                fixed[var.get_id()] = lo
    for var, value in list(zip(v.x[-1], last.object_pose)) + list(zip(v.q[-1], last.q)):
        assert fixed[var.get_id()] == value
    for var in np.concatenate([v.xdd[0], v.qdd[0], v.xdd[-1], v.qdd[-1], v.xd[-1], v.qd[-1]]):
        assert fixed[var.get_id()] == 0.0
    assert not any(var.get_id() in fixed for var in v.x[5])  # the knots between stay free


def test_keyframes_plan_is_continuous_at_the_nodes_and_physical(scene, contact_plan, serial):
    assert serial.success, serial.status
    assert serial.formulation == "keyframes" and len(serial.segments) == 2
    a, M = serial.trajectory, CONFIG.cito.knots_per_segment
    assert a.x.shape == (2 * M + 1, 3)
    np.testing.assert_allclose(np.diff(a.t), CONFIG.cito.dt)
    for n, node in enumerate(contact_plan.nodes):
        k = n * M
        np.testing.assert_array_equal(a.x[k], node.object_pose)  # exactly the node: fixed, not solved for
        np.testing.assert_array_equal(a.q[k], node.q)
        assert not a.xdot[k].any() and not a.qdot[k].any()
    assert a.x[-1, 2] == contact_plan.nodes[-1].object_pose[2]  # the final pose is the goal node's
    # The plan's own check of the stitched arrays, recomputed here from them alone.
    check = check_physics(a.arrays(), ObjectModel.from_scene(scene), mu_plan(CONFIG.scene, CONFIG.search))
    assert check.passed and check == serial.physics_check, check.reason
    assert check.newton_euler_force_N < 1e-6
    for record in serial.segments:  # this goal's plan (the fingers kept apart) needs no link retry
        assert record["success"] and record["iterations"] > 0
        assert [r["kind"] for r in record["attempts"]] in (["keyframes"], ["keyframes", "links"])
    assert [len(r["attempts"]) for r in serial.segments] == [1, 1]
    assert serial.iterations == sum(r["iterations"] for r in serial.segments)


def test_stitch_averages_the_forces_at_a_shared_knot(serial):
    # Split the stitched plan at node 1 and stitch it again: the same arrays, the shared knot's
    # forces the mean of two copies whose forces differ by +-d.
    M = CONFIG.cito.knots_per_segment
    a = serial.trajectory

    def piece(lo, hi, shift):
        arrays = {n: getattr(a, n)[lo:hi].copy() for n in TRAJECTORY_ARRAYS}
        k = 0 if lo else -1
        for n in ("tau", "lambda_n", "lambda_t", "f_W"):
            arrays[n][k] += shift
        return _Piece(trajectory=type(a)(**arrays))

    out = stitch([piece(0, M + 1, 0.25), piece(M, 2 * M + 1, -0.25)])
    for n in TRAJECTORY_ARRAYS:
        np.testing.assert_allclose(getattr(out, n), getattr(a, n), rtol=0, atol=1e-12)
    moved = piece(M, 2 * M + 1, 0.0)
    moved.trajectory.x[0, 2] += 1e-9  # pieces that do not meet are a bug, never averaged
    with pytest.raises(AssertionError, match="differ in x"):
        stitch([piece(0, M + 1, 0.0), moved])


@dataclasses.dataclass(frozen=True)
class _Piece:
    """What stitch reads of a PieceResult."""

    trajectory: object
    first: int = 0
    last: int = 1


def assert_same_plan(other, serial):
    for name in TRAJECTORY_ARRAYS:
        np.testing.assert_array_equal(getattr(other.trajectory, name), getattr(serial.trajectory, name))
    assert other.iterations == serial.iterations and other.cost == serial.cost


def test_parallel_and_serial_solves_give_identical_arrays(scene, contact_plan, serial):
    parallel = plan(
        scene=scene, goal=GOAL, method="trajectotree", config=CONFIG, contact_plan=contact_plan, segment_workers=2
    )
    assert_same_plan(parallel, serial)


@pytest.mark.slow  # two more plans in worker processes (the quick suite solves in parallel above)
def test_a_given_executor_reused_across_plans_gives_identical_arrays(scene, contact_plan, serial):
    with local_pool(2) as pool:  # a given executor, reused across plans
        given = [
            plan(
                scene=scene,
                goal=GOAL,
                method="trajectotree",
                config=CONFIG,
                contact_plan=contact_plan,
                segment_executor=pool,
            )
            for _ in range(2)
        ]
    for other in given:
        assert_same_plan(other, serial)


@pytest.mark.slow
def test_segments_on_a_dask_cluster_equal_the_serial_solve(scene, contact_plan, serial):
    from distributed import Client, LocalCluster

    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, protocol="tcp", host="127.0.0.1", dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        result = plan(
            scene=scene,
            goal=GOAL,
            method="trajectotree",
            config=CONFIG,
            contact_plan=contact_plan,
            segment_executor=client.get_executor(),
        )
        worker_pids = set(client.run(lambda: __import__("os").getpid()).values())
    for name in TRAJECTORY_ARRAYS:
        np.testing.assert_array_equal(getattr(result.trajectory, name), getattr(serial.trajectory, name))
    # each segment was solved in a worker process of the cluster, not here
    assert {a["pid"] for s in result.segments for a in s["attempts"]} <= worker_pids


def test_a_failing_segment_is_retried_and_recorded(scene, contact_plan, tmp_path):
    # max_iter 3: no attempt converges; every segment is tried 5 times (its own program, a restart
    # from its last iterate, itself with the pinned fingers held harder, the joint program with its
    # neighbours: here both segments at once, and that joint program again held harder).
    config = dataclasses.replace(CONFIG, cito=dataclasses.replace(CONFIG.cito, max_iter=3))
    result = plan(
        scene=scene, goal=GOAL, method="trajectotree", config=config, contact_plan=contact_plan, segment_workers=1
    )
    assert not result.success and not result.converged
    assert "failed after retries" in result.status and "Max iteration exceeded" in result.status
    save_plan(result, tmp_path)
    data = json.loads((tmp_path / "plan.json").read_text())
    assert data["formulation"] == "keyframes" and data["config"]["cito"]["formulation"] == "keyframes"
    for s, record in enumerate(data["segments"]):
        assert record["retries"] == 4 and record["nodes"] == [s, s + 1] and not record["success"]
        assert [(r["kind"], r["nodes"]) for r in record["attempts"]] == [
            ("keyframes", [s, s + 1]),
            ("restart", [s, s + 1]),
            ("strict", [s, s + 1]),
            ("joint", [0, 2]),
            ("strict", [0, 2]),
        ]
        assert all(r["iterations"] == 3 for r in record["attempts"])
    assert data["iterations"] == 8 * 3  # 2 segments x 3 attempts + a joint and a strict joint retry
    assert load_plan(tmp_path).segments == tuple(data["segments"])
    assert result.trajectory.x.shape == (2 * CONFIG.cito.knots_per_segment + 1, 3)  # still saved, as joint's


def test_a_restart_rescues_segments_stopped_short(scene, contact_plan):
    # max_iter 14 stops both segments short (they need 21 and 16 iterations here, 16 and 14 without
    # the link rows); the restart from the last iterate converges within 14 more (11 and 12), so the
    # plan succeeds with one retry per segment.
    # The link rows in every segment from the start (not on demand), so no "links" attempt intervenes.
    config = dataclasses.replace(CONFIG, cito=dataclasses.replace(CONFIG.cito, max_iter=14, link_rows_on_demand=False))
    result = plan(
        scene=scene, goal=GOAL, method="trajectotree", config=config, contact_plan=contact_plan, segment_workers=1
    )
    assert result.success and result.physics_check.passed, result.status
    for record in result.segments:
        assert record["success"] and record["retries"] == 1
        assert [(r["kind"], r["success"]) for r in record["attempts"]] == [("keyframes", False), ("restart", True)]
        assert record["attempts"][0]["status"] == "Max iteration exceeded"


@pytest.mark.slow  # a plan whose joint retry converges (seconds; the quick suite runs the retries to their end above)
def test_a_segment_failing_the_physics_check_is_retried_with_its_neighbours(scene, contact_plan):
    # Node 1's finger 2 turned 0.1 rad off its grasp (a keyframe the search would not make): segment
    # 1-2 converges but its fingertip pushes from a distance, so (no restart: it converged), after its
    # strict attempt alone fails too (so does segment 0-1's), the joint program over nodes 0-2, which frees
    # node 1, replaces both.
    node = contact_plan.nodes[1]
    q = node.q.copy()
    q[4] += 0.1
    bad = dataclasses.replace(
        contact_plan, nodes=(contact_plan.nodes[0], dataclasses.replace(node, q=q), contact_plan.nodes[2])
    )
    config = dataclasses.replace(CONFIG, cito=dataclasses.replace(CONFIG.cito, link_rows_on_demand=False))
    result = plan(scene=scene, goal=GOAL, method="trajectotree", config=config, contact_plan=bad, segment_workers=1)
    assert result.success and result.physics_check.passed, result.status
    first, second = result.segments
    assert [(r["kind"], r["success"]) for r in second["attempts"]] == [
        ("keyframes", False),
        ("strict", False),
        ("joint", True),
    ]
    assert second["attempts"][0]["status"] in ("Success", "Stop at acceptable point")  # converged
    assert [(r["kind"], r["nodes"]) for r in first["attempts"]] == [
        ("keyframes", [0, 1]),
        ("strict", [0, 1]),
        ("joint", [0, 2]),
    ]
    assert first["success"] and second["success"] and first["retries"] == second["retries"] == 2
    np.testing.assert_array_equal(result.trajectory.x[-1], contact_plan.nodes[-1].object_pose)


def test_joint_retries_take_the_neighbours_and_merge_overlaps():
    assert _neighbour_ranges([4], 9) == [(3, 6)]  # nodes 3..6: segments 3, 4, 5
    assert _neighbour_ranges([0], 9) == [(0, 2)] and _neighbour_ranges([8], 9) == [(7, 9)]
    assert _neighbour_ranges([2, 4], 9) == [(1, 6)]  # overlapping: one program
    assert _neighbour_ranges([1, 5], 9) == [(0, 3), (4, 7)]  # apart: two
    assert _neighbour_ranges([0], 1) == []  # one segment: nothing to free (its chain held it harder alone)


@pytest.mark.slow
def test_the_demo_goal_plans_physically_on_the_paper_like_search():
    """The demo's goal pi/2 (9 segments) on the paper-like search's plan (search.rolled_stances false,
    search.max_stance_force 0, search.push_capacity 0). Before the fingers were kept apart its segment 5
    needed the joint and then the strict retry of nodes 4-7; its plan now passes at the first attempt. No
    seed-0 goal of the 39 tried since goes through the strict retry and passes (1.166 and 1.184 go through
    it and still fail the check: an open fault, docs/measurements.md), so the strict retry's success is
    pinned by no test now; test_a_failing_segment_is_retried_and_recorded pins its order."""
    config = Config(search=SearchConfig(rolled_stances=False, max_stance_force=0.0, push_capacity=0.0))
    result = plan(
        scene=build_scene(config.scene), goal=np.pi / 2, method="trajectotree", config=config, segment_workers=1
    )
    assert result.success and result.physics_check.passed, result.status
    assert [r["kind"] for r in result.segments[5]["attempts"]] == ["keyframes"]


def test_bad_input_is_refused(scene, tmp_path, capsys):
    with pytest.raises(ConfigError, match=r"cito.formulation = 'fast' is unknown; valid: keyframes, joint"):
        CitoConfig(formulation="fast")
    for workers in (0, -1, 1.5, True):
        with pytest.raises(ConfigError, match="segment_workers"):
            plan(scene=scene, goal=GOAL, method="trajectotree", config=CONFIG, segment_workers=workers)
    for args, message in (
        (["--formulation", "fast"], "--formulation (cito.formulation) = 'fast' is unknown; valid: keyframes, joint"),
        (["--segment-workers", "0"], "--segment-workers = 0 is out of range; valid range: [1, inf)"),
    ):
        out = tmp_path / "out"
        assert main(["plan", "--goal", "0.3", *args, "--out", str(out)]) == 2
        assert message in capsys.readouterr().err
        assert not out.exists()
