"""The link rows (cito/links.py) against independent references: finite differences of their
values, the search's own link geometry (Reachability.link_polygons, from SceneGraph's boxes)
and, end to end, the exact separating-axis test on a keyframes segment whose links went
through the box without them."""

import dataclasses

import numpy as np
import pytest

from trajectotree.cito.knot import BodyParams
from trajectotree.cito.links import LINK_FRACTIONS, LinkRows
from trajectotree.cito.program import build_program, link_knots
from trajectotree.cito.transition import piece_spec, transition_spec
from trajectotree.config import CitoConfig, Config, ConfigError, ObjectConfig, SceneConfig, mu_plan
from trajectotree.geometry import rotation_2d
from trajectotree.planning.keyframes import solve_segments
from trajectotree.planning.piece import PieceTask, solve_piece
from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.reach import Reachability, rectangles_overlap_polygon
from trajectotree.search.tree import find_contact_plan

TRIANGLE = tuple((0.08 * np.cos(a), 0.08 * np.sin(a)) for a in np.pi / 2 + 2 * np.pi / 3 * np.arange(3))
# Goal -2.884 rad of seed 0 (the search keeping the fingers apart): in segment 4 (nodes 4-5), without the
# link rows, finger 1's links 1 and 2 cut 25 mm into the box.
GOAL, SEGMENT = -2.8841484100105235, 4
CONFIG = Config()


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module", params=["box", "triangle", "five"])
def rows(request, scene):
    """The box's and the triangle's link rows, and the five-finger hand's (3 + 10 columns)."""
    if request.param == "triangle":
        scene = build_scene(SceneConfig(object=ObjectConfig(vertices=TRIANGLE)))
    elif request.param == "five":
        scene = build_scene(SceneConfig(hand="planar_hand5"))
    return LinkRows(BodyParams(scene, 1000.0, mu=0.5), 4)


def random_knots(rows, n, seed):
    """(x, q) blocks: the object within 5 cm of the origin, joints anywhere in [-1, 1] rad (links
    inside and outside the object)."""
    rng = np.random.default_rng(seed)
    Z = rng.uniform(-1, 1, (n, rows.link_size))
    Z[:, :2] *= 0.05
    return Z


def test_link_jacobian_matches_finite_differences(rows):
    Z = random_knots(rows, 4, seed=3)
    assert Z.shape[1] == 3 + 2 * rows.num_fingers
    val, jac = rows.evaluate(Z, True)
    assert val.min() < 0 < val.max()  # some rows violated, some not
    h = 1e-6
    for k in range(4):
        fd = np.zeros_like(jac[k])
        for j in range(Z.shape[1]):
            dZ = np.zeros_like(Z)
            dZ[k, j] = h
            fd[:, j] = (rows.evaluate(Z + dZ, False)[0][k] - rows.evaluate(Z - dZ, False)[0][k]) / (2 * h)
        np.testing.assert_allclose(jac[k], fd, atol=1e-7, err_msg=f"knot {k}")


def test_declared_sparsity_is_the_support_of_the_derivative(rows):
    h = 1e-6
    support = set()
    for z in random_knots(rows, 3, seed=11):
        for j in range(len(z)):
            dz = np.zeros(len(z))
            dz[j] = h
            fd = (rows.values_one(z + dz) - rows.values_one(z - dz)) / (2 * h)
            support |= {(int(i), j) for i in np.flatnonzero(np.abs(fd) > 1e-9)}
    assert support == set(rows.sparsity())


def test_one_knot_paths_agree_with_the_batch(rows):
    """program._KnotCache serves a knot from a batch or alone: the same numbers (the scalar
    values_one to rounding: math's exp and log against numpy's)."""
    Z = random_knots(rows, 4, seed=4)
    val, jac = rows.evaluate(Z, True)
    for k in range(4):
        np.testing.assert_allclose(rows.values_one(Z[k]), val[k], rtol=0, atol=1e-15)
        v1, j1 = rows.knot(k).evaluate(Z[k : k + 1], True)
        np.testing.assert_array_equal(v1[0], val[k])
        np.testing.assert_array_equal(j1[0], jac[k])


def test_rows_against_the_searchs_link_boxes(scene):
    """The rows against face distances computed from the corners of the search's link boxes
    (Reachability.link_polygons): a point row (gap + w) lies within [max_j d_j, max_j d_j + log(V)/k]
    of the object's face distances d_j at that point of the centreline, a vertex row likewise
    for the link-2 box's four face distances at that object vertex."""
    rows, reach, shape = LinkRows(BodyParams(scene, 1000.0, mu=0.5), 1), Reachability(scene), scene.config.shape
    P, V = rows.points.per_finger, len(shape.vertices)
    for z in random_knots(rows, 5, seed=5):
        pose, q, val = z[:3], z[3:], rows.values_one(z)
        point_rows, vertex_rows = (
            val[: NUM_FINGERS * P].reshape(NUM_FINGERS, P),
            val[NUM_FINGERS * P :].reshape(NUM_FINGERS, V),
        )
        p_WV = pose[:2] + shape.vertices @ rotation_2d(pose[2]).T
        for i in range(NUM_FINGERS):
            boxes = reach.link_polygons(i, q[2 * i : 2 * i + 2])
            points = []
            for corners, fractions in zip(boxes, LINK_FRACTIONS):
                near, far = 0.5 * (corners[2] + corners[3]), 0.5 * (corners[0] + corners[1])  # ends of the centreline
                points += [near + f * (far - near) for f in fractions]
            p_BL = (np.array(points) - pose[:2]) @ rotation_2d(pose[2])
            face_max = np.max(p_BL @ shape.normals.T - shape.offsets, axis=1)
            w = scene.fingers[i].link_boxes[0].half_width
            assert np.all(point_rows[i] + w >= face_max - 1e-12)
            assert np.all(point_rows[i] + w <= face_max + np.log(V) / 1000.0 + 1e-12)
            c = boxes[1]  # link 2's corners, counter-clockwise from (+l, -w)
            u = (c[0] - c[3]) / np.linalg.norm(c[0] - c[3])
            rel = p_WV - c.mean(axis=0)
            dx, dy = rel @ u, rel @ np.array([-u[1], u[0]])
            hl, hw = 0.5 * np.linalg.norm(c[0] - c[3]), 0.5 * np.linalg.norm(c[1] - c[0])
            box_max = np.max([dx - hl, -dx - hl, dy - hw, -dy - hw], axis=0)
            assert np.all(vertex_rows[i] >= box_max - 1e-12)
            assert np.all(vertex_rows[i] <= box_max + np.log(4) / 1000.0 + 1e-12)


def test_rows_at_the_free_knots_and_none_when_off(scene):
    contact_plan = find_contact_plan(scene, 0.3, dataclasses.replace(CONFIG.search, num_nodes=3))
    body = BodyParams(scene, CONFIG.cito.sdf_sharpness, mu=mu_plan(CONFIG.scene, CONFIG.search))
    piece = piece_spec(contact_plan, 0, 1, radius=scene.tip_radius, config=CONFIG.cito)
    joint = transition_spec(contact_plan, radius=scene.tip_radius, config=CONFIG.cito)
    assert link_knots(piece) == list(range(1, piece.num_knots - 1))  # both ends fixed at the nodes
    assert link_knots(joint) == list(range(1, joint.num_knots))  # only x_0, q_0 fixed
    program = build_program(CONFIG.cito, piece, body)
    assert [b.evaluator().get_description() for b in program.link_bindings] == [f"links{k}" for k in link_knots(piece)]
    off = build_program(dataclasses.replace(CONFIG.cito, link_rows=False), piece, body)
    assert off.link_bindings == []
    assert not any(b.evaluator().get_description().startswith("links") for b in off.prog.GetAllConstraints())
    assert len(off.prog.GetAllConstraints()) == len(program.prog.GetAllConstraints()) - len(program.link_bindings)


def test_link_config_is_checked():
    assert CitoConfig().link_rows and CitoConfig().link_clearance == 0.001
    with pytest.raises(ConfigError, match=r"cito.link_clearance = -0.001 is out of range; valid range: \[0, 0.02\]"):
        CitoConfig(link_clearance=-0.001)
    with pytest.raises(ConfigError, match="cito.link_rows"):
        CitoConfig(link_rows=1)


def links_overlap(scene, trajectory) -> list[tuple[int, int, int]]:
    """(knot, finger, link) of every link box overlapping the object (exact separating axes)."""
    reach, shape, hits = Reachability(scene), scene.config.shape, []
    for k, (pose, q) in enumerate(zip(trajectory.x, trajectory.q)):
        R_BW = rotation_2d(-pose[2])
        for i in range(NUM_FINGERS):
            for j, corners in enumerate(reach.link_polygons(i, q[2 * i : 2 * i + 2])):
                rect = scene.fingers[i].link_boxes[j]
                centre_B = R_BW @ (corners.mean(axis=0) - pose[:2])
                axis = corners[0] - corners[3]
                angle = np.arctan2(axis[1], axis[0]) - pose[2]
                if rectangles_overlap_polygon(shape, centre_B, angle, rect.half_length, rect.half_width)[0]:
                    hits.append((k, i, j + 1))
    return hits


@pytest.fixture(scope="module")
def goal_plan(scene):
    """The search's contact plan of GOAL, in the paper's order of its children (whose segment SEGMENT
    has a link cut the box without the link rows)."""
    contact_plan = find_contact_plan(scene, GOAL, dataclasses.replace(CONFIG.search, push_capacity=0.0))
    assert contact_plan.success, contact_plan.reason
    return contact_plan


def test_segment_whose_link_cut_the_box_is_clear_with_the_rows(scene, goal_plan):
    contact_plan = goal_plan

    def segment(cito):
        task = PieceTask(
            CONFIG.scene, cito, mu_plan(CONFIG.scene, CONFIG.search), contact_plan, SEGMENT, SEGMENT + 1, "keyframes"
        )
        return solve_piece(task)

    without = segment(dataclasses.replace(CONFIG.cito, link_rows=False))
    assert without.converged and {(i, j) for _, i, j in links_overlap(scene, without.trajectory)} == {(1, 1), (1, 2)}
    assert not without.success and "a link of finger 1 overlaps the box" in without.check.reason  # the check's rule
    with_rows = segment(CONFIG.cito)
    assert with_rows.success, with_rows.status
    assert links_overlap(scene, with_rows.trajectory) == []


@pytest.mark.slow
def test_on_demand_that_segment_alone_is_solved_again_with_the_rows(goal_plan):
    """On demand segment 5 alone is solved again with the rows, and every segment of GOAL's plan ends
    clear of the box: all nine solved (seconds; the quick suite sees the "links" attempt on
    tests/planning/test_keyframes.py's two-segment plan). Without the rows predicted before the first
    solve (cito.link_rows_predicted, which gives this segment its rows at once: test_link_rows_predicted)."""
    on_demand = dataclasses.replace(CONFIG, cito=dataclasses.replace(CONFIG.cito, link_rows_predicted=False))
    pieces, attempts = solve_segments(goal_plan, on_demand, workers=1)
    assert [r.kind for r in attempts[SEGMENT]] == ["keyframes", "links"] and all(p.success for p in pieces)
    assert all(p.check.link_penetration_m <= 1e-3 for p in pieces)
