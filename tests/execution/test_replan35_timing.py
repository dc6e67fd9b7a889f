"""A replan's event splits its latency (issue 35): the search's time, its first segment's attempts (builds
and IPOPT solves) and their iterations, for a plan and for a first segment that failed. Real plans of goal
0.3 rad (2 segments of 12 knots), replanned from the planned state at node 1."""

import dataclasses

import pytest

from trajectotree.config import Config, SearchConfig
from trajectotree.execution.replan import Deadlines, PlanePlanning, replan
from trajectotree.planning.planners import plan
from trajectotree.results import ReplanOutcome, ReplanReason
from trajectotree.scene.plant import build_scene
from trajectotree.start import StartState

GOAL = 0.3
TWO = Config(search=SearchConfig(num_nodes=3, push_capacity=0.0))
ROOMY = Deadlines(search_s=30.0, first_segment_s=300.0)  # this test is about the record, not the time


@pytest.fixture(scope="module")
def planned():
    scene = build_scene(TWO.scene)
    first = plan(goal=GOAL, config=TWO, scene=scene, segment_workers=1)
    assert first.success, first.status
    k = TWO.cito.knots_per_segment
    return scene, first, StartState(object_pose=tuple(first.trajectory.x[k]), q=tuple(first.trajectory.q[k]))


def test_a_replans_latency_is_split_into_its_search_and_first_segment(planned):
    scene, first, start = planned
    event, solved = replan(PlanePlanning(first, TWO, scene, 1), start, 1.2, ReplanReason.FRICTION, 0.6, 0.05, ROOMY)
    assert event.outcome is ReplanOutcome.PLANNED, event.status
    attempts = solved.new.segments[0]["attempts"]
    assert event.first_segment_iterations == sum(a["iterations"] for a in attempts) > 0
    assert 0 < event.search_s and 0 < event.first_segment_s
    assert event.search_s + event.first_segment_s < event.latency_s  # and the rest: checks, arrays
    record = event.to_json()
    assert record["first_segment_s"] == event.first_segment_s and record["first_segment_iterations"] > 0


def test_a_failed_first_segment_records_every_attempt(planned):
    scene, first, start = planned
    failing = dataclasses.replace(TWO, cito=dataclasses.replace(TWO.cito, max_iter=3))  # no attempt converges
    event, solved = replan(PlanePlanning(first, failing, scene, 1), start, 1.2, ReplanReason.FRICTION, 0.6, 0.05, ROOMY)
    assert event.outcome is ReplanOutcome.FIRST_SEGMENT_FAILED and solved is None, event.status
    assert event.first_segment_iterations == 9  # its first solve, its restart and its strict attempt: 3 each
    assert event.search_s + event.first_segment_s < event.latency_s
