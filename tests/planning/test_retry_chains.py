"""Retry chains instead of rounds (issue 35): a segment's first solve, its restart, its link-rows retry
and its strict attempt alone run as one task on the worker pool (piece.solve_chain), so a failing
segment's retries start while other segments still wait for their first solve; the joint retries
follow for the segments whose chain failed; a plan without retries is its first attempts stitched.
Real plans of goal 0.3 rad (3 segments of 12 knots, and the 2-segment plan of test_keyframes)."""

import dataclasses
import os
import time

import numpy as np
import pytest

from trajectotree.config import Config, SearchConfig, mu_plan
from trajectotree.planning.keyframes import solve_first_segment_first, solve_segments, stitch
from trajectotree.planning.piece import PieceTask, attempt_config, solve_piece
from trajectotree.planning.planners import plan
from trajectotree.results import TRAJECTORY_ARRAYS
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

GOAL = 0.3
THREE = Config(search=SearchConfig(num_nodes=4, push_capacity=0.0))  # 3 segments: more than the 2 workers
TWO = Config(search=SearchConfig(num_nodes=3, push_capacity=0.0))  # 2 segments, both pass at their first solve
# max_iter 3: no attempt converges, so every segment runs its whole chain and the joint retries follow
FAILING = dataclasses.replace(THREE, cito=dataclasses.replace(THREE.cito, max_iter=3))


@pytest.fixture(scope="module")
def scene():
    return build_scene(THREE.scene)


@pytest.fixture(scope="module")
def three(scene):
    result = find_contact_plan(scene, GOAL, THREE.search)
    assert result.success and len(result.nodes) == 4, result.reason
    return result


@pytest.fixture(scope="module")
def failing(three):
    """solve_segments of the 3-segment plan on 2 worker processes, every attempt failing."""
    return solve_segments(three, FAILING, workers=2)


def test_a_failing_segment_starts_its_retries_before_the_others_first_solves(failing):
    pieces, attempts = failing
    chains = {s: [r for r in tried if r.last - r.first == 1] for s, tried in attempts.items()}
    for s, chain in chains.items():  # each chain in one task: one process, its attempts back to back
        assert [r.kind for r in chain] == ["keyframes", "restart", "strict"], s
        assert len({r.pid for r in chain}) == 1 and chain[0].pid != os.getpid()
        assert all(a.started_s < b.started_s for a, b in zip(chain, chain[1:]))
    # With rounds every first solve started before any restart; with chains on 2 processes the
    # third segment's first solve waits for a whole chain, so a restart has started before it.
    first_restart = min(chain[1].started_s for chain in chains.values())
    last_first_solve = max(chain[0].started_s for chain in chains.values())
    assert first_restart < last_first_solve
    assert not any(p.success for p in pieces)


def test_the_joint_retries_follow_for_the_segments_whose_chain_failed(failing):
    pieces, attempts = failing
    for s, tried in attempts.items():
        assert [(r.kind, r.first, r.last) for r in tried[3:]] == [("joint", 0, 3), ("strict", 0, 3)], s
        assert all(r.iterations == 3 for r in tried)
    joint = attempts[0][3]
    assert attempts[1][3] is joint and attempts[2][3] is joint  # one joint program over all three segments
    assert joint.started_s > max(r.started_s for tried in attempts.values() for r in tried[:3])
    assert [(p.kind, p.first, p.last) for p in pieces] == [("strict", s, s + 1) for s in range(3)]


def test_a_plan_without_retries_is_its_first_solves_stitched_bit_for_bit(scene):
    contact_plan = find_contact_plan(scene, GOAL, TWO.search)
    result = plan(
        scene=scene, goal=GOAL, method="trajectotree", config=TWO, contact_plan=contact_plan, segment_workers=2
    )
    assert result.success, result.status
    assert [[a["kind"] for a in s["attempts"]] for s in result.segments] == [["keyframes"], ["keyframes"]]
    # The round that was: each segment's first program, solved here in this process.
    mu = mu_plan(TWO.scene, TWO.search)
    cito = attempt_config(TWO.cito, "keyframes")
    first = [solve_piece(PieceTask(TWO.scene, cito, mu, contact_plan, s, s + 1, "keyframes"), scene) for s in (0, 1)]
    expected = stitch(first)
    for name in TRAJECTORY_ARRAYS:
        np.testing.assert_array_equal(getattr(result.trajectory, name), getattr(expected, name))
    assert result.iterations == sum(r.iterations for r in first)
    assert result.cost == float(sum(r.cost for r in first))


def test_replanning_solves_segment_zero_first_here_and_the_rest_after_it(scene, three):
    since = time.perf_counter()
    pieces, attempts, ready = solve_first_segment_first(three, THREE, workers=2, scene=scene, since=since)
    assert all(p.success for p in pieces) and [(p.first, p.last) for p in pieces] == [(0, 1), (1, 2), (2, 3)]
    assert {r.pid for r in attempts[0]} == {os.getpid()}  # segment 0 alone, in this process
    rest = [r for s in (1, 2) for r in attempts[s]]
    assert os.getpid() not in {r.pid for r in rest}  # the rest on the pool's processes
    assert min(r.started_s for r in rest) > max(r.started_s for r in attempts[0])  # after segment 0
    assert 0 < ready[0] <= min(ready[1:]) and max(ready) < time.perf_counter() - since
