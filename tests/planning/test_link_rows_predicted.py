"""Link rows decided before solving (issue 35 item 1, cito.link_rows_predicted): a keyframes segment whose
straight joint path between its nodes, the object held at the first node's pose, puts a link inside the
object gets the link rows of that path's fingers and of those whose links lie near the object at a node in
its first solve, and needs no "links" retry. Real segment: goal -2.884 rad, nodes 4-5, where the switching
finger is 3 and finger 1, holding the box, cut 25 mm into it when solved without rows."""

import dataclasses

import pytest

from trajectotree.config import CitoConfig, Config, ConfigError, mu_plan
from trajectotree.planning.physics import link_penetrations
from trajectotree.planning.piece import PieceTask, overlaps, predicted_link_fingers, solve_chain
from trajectotree.results import LINK_PENETRATION_TOL
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

GOAL, SEGMENT = -2.8841484100105235, 4
CONFIG = Config()
UNPREDICTED = dataclasses.replace(CONFIG.cito, link_rows_predicted=False)


@pytest.fixture(scope="module")
def scene():
    return build_scene(CONFIG.scene)


@pytest.fixture(scope="module")
def contact_plan(scene):
    result = find_contact_plan(scene, GOAL, CONFIG.search)
    assert result.success, result.reason
    return result


def task(contact_plan, segment: int, cito: CitoConfig = CONFIG.cito) -> PieceTask:
    mu = mu_plan(CONFIG.scene, CONFIG.search)
    return PieceTask(CONFIG.scene, cito, mu, contact_plan, segment, segment + 1, "keyframes")


def fingers_inside(result, scene) -> set:
    a = result.trajectory
    depth = link_penetrations(a.x, a.q, scene.fingers, CONFIG.scene.shape).max(axis=(0, 2))
    return {i for i, d in enumerate(depth) if d > LINK_PENETRATION_TOL}


def test_without_the_prediction_the_segment_needs_the_links_retry(scene, contact_plan):
    tried = solve_chain(task(contact_plan, SEGMENT, UNPREDICTED), scene)
    assert overlaps(tried[0].check) and fingers_inside(tried[0], scene) == {1}
    assert [r.kind for r in tried] == ["keyframes", "links"] and tried[-1].success


def test_a_predicted_segment_gets_its_fingers_rows_first_and_no_retry(scene, contact_plan):
    fingers = predicted_link_fingers(task(contact_plan, SEGMENT), scene)
    switching = contact_plan.nodes[SEGMENT + 1].switching_finger
    assert switching in fingers and 1 in fingers and len(fingers) < scene.num_fingers
    tried = solve_chain(task(contact_plan, SEGMENT), scene)
    assert [r.kind for r in tried] == ["keyframes"]
    assert tried[0].success and not overlaps(tried[0].check) and fingers_inside(tried[0], scene) == set()


def test_a_segment_whose_path_keeps_the_links_out_is_first_solved_without_rows(scene, contact_plan):
    unflagged = [
        s for s in range(len(contact_plan.nodes) - 1) if not predicted_link_fingers(task(contact_plan, s), scene)
    ]
    assert unflagged  # most segments never bring a link near the object
    first = solve_chain(task(contact_plan, unflagged[0]), scene)[0]
    bare = solve_chain(task(contact_plan, unflagged[0], UNPREDICTED), scene)[0]
    assert first.iterations == bare.iterations and first.cost == bare.cost  # the same program: no rows


def test_no_prediction_without_on_demand_rows(contact_plan, scene):
    always = dataclasses.replace(CONFIG.cito, link_rows_on_demand=False)
    assert predicted_link_fingers(task(contact_plan, SEGMENT, always), scene) == ()


@pytest.mark.parametrize("value", ["yes", 1, None])
def test_a_bad_link_rows_predicted_is_refused_by_name(value):
    with pytest.raises(ConfigError, match="cito.link_rows_predicted"):
        CitoConfig(link_rows_predicted=value)
