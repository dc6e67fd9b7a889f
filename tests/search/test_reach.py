"""Reachability: closed-form IK, Drake IK and the link-vs-box collision test."""

import numpy as np
import pytest

from trajectotree.scene.plant import NUM_FINGERS, build_scene
from trajectotree.search.reach import Reachability


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def reach(scene):
    return Reachability(scene)


def test_closed_form_ik_inverts_the_plant_kinematics(scene):
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = np.concatenate([rng.uniform(f.q_lower, f.q_upper) for f in scene.fingers])
        p_WF = scene.fingertip_positions(q)
        for i, finger in enumerate(scene.fingers):
            solutions = finger.ik_solutions(p_WF[i])
            # joint 2 in [0.1, 2.6]: one elbow branch, so exactly one solution
            assert len(solutions) == 1
            np.testing.assert_allclose(solutions[0], q[2 * i : 2 * i + 2], atol=1e-9)


def test_drake_ik_touches_the_box_and_agrees_with_the_closed_form(scene, reach):
    pose = (0.0, 0.0, 0.3)
    q = np.zeros(8)
    for i, s in enumerate((0.55, 0.15, 0.25, 0.45)):
        result = reach.solve(pose, i, s)
        assert result.reachable, result.refusal
        np.testing.assert_allclose(result.q, reach.closed_form(pose, i, s).q, atol=1e-5)
        q[2 * i : 2 * i + 2] = result.q
        f = scene.fingers[i]
        assert np.all(result.q >= f.q_lower - 1e-9) and np.all(result.q <= f.q_upper + 1e-9)
    # The plant puts each fingertip sphere tangent to the box at its contact.
    p_WF = scene.fingertip_positions(q)
    for i, s in enumerate((0.55, 0.15, 0.25, 0.45)):
        np.testing.assert_allclose(p_WF[i], reach.tip_target(pose, s), atol=1e-5)
        assert reach.boundary.signed_distance(_R(-pose[2]) @ p_WF[i]) == pytest.approx(scene.tip_radius, abs=1e-5)


def _R(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def test_out_of_reach_contacts_fail_in_drake_ik_too(reach):
    # Finger 0 (bottom right) cannot reach the top-left corner region: the closed form finds
    # no solution, and Drake IK from several seeds agrees (the closed-form filter is exact).
    pose, s = (0.0, 0.0, 0.0), 0.28
    assert reach.fingers[0].ik_solutions(reach.tip_target(pose, s)) == []
    assert not reach.solve(pose, 0, s).reachable
    for seed in ([0.0, 1.0], [-1.2, 2.0], [1.2, 0.5]):
        assert reach._drake_ik(0, reach.tip_target(pose, s), np.array(seed)) is None


def test_cache_skips_repeated_ik(reach):
    pose = (0.0, 0.0, -0.2)
    reach.solve(pose, 1, 0.16)
    calls = reach.ik_calls
    reach.solve(pose, 1, 0.16)
    reach.solve(pose, 1, 0.16 + reach.boundary.perimeter)
    assert reach.ik_calls == calls


def signed_distances(scene, pose, q):
    """SceneGraph signed distance between each finger's link boxes and the box (finger, link)."""
    context = scene.diagram.CreateDefaultContext()
    scene.plant.SetPositions(scene.plant.GetMyMutableContextFromRoot(context), scene.positions(pose, q))
    query = scene.scene_graph.get_query_output_port().Eval(scene.scene_graph.GetMyContextFromRoot(context))
    inspector = query.inspector()
    (box,) = scene.plant.GetCollisionGeometriesForBody(scene.plant.GetBodyByName("box", scene.box))
    out = np.zeros((NUM_FINGERS, 2))
    for i in range(NUM_FINGERS):
        for j in (1, 2):
            body = scene.plant.GetBodyByName(f"finger{i}_link{j}", scene.hand)
            (link,) = [
                g
                for g in scene.plant.GetCollisionGeometriesForBody(body)
                if type(inspector.GetShape(g)).__name__ == "Box"
            ]
            out[i, j - 1] = query.ComputeSignedDistancePairClosestPoints(link, box).distance
    return out


def check_link_collisions_against_scene_graph(scene, reach, seed: int, min_each: int) -> None:
    """Reachability.links_penetrate vs SceneGraph's signed distances at random poses and angles."""
    rng = np.random.default_rng(seed)
    counts = {True: 0, False: 0}
    for _ in range(150):
        pose = (rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), rng.uniform(-np.pi, np.pi))
        q = np.concatenate([rng.uniform(f.q_lower, f.q_upper) for f in scene.fingers])
        distances = signed_distances(scene, pose, q)
        for i in range(NUM_FINGERS):
            if np.min(np.abs(distances[i])) < 1e-4:
                continue  # grazing contact: either answer is acceptable
            expected = bool(np.min(distances[i]) < 0)
            assert reach.links_penetrate(pose, i, q[2 * i : 2 * i + 2]) == expected
            counts[expected] += 1
    assert counts[True] > min_each and counts[False] > min_each  # both outcomes were exercised


def test_planar_collision_test_matches_scene_graph(scene, reach):
    check_link_collisions_against_scene_graph(scene, reach, seed=3, min_each=20)


def test_link_polygons_follow_the_plant(scene, reach):
    # The far end of link 2's collision box sits 0.085 m from joint 2 along the link.
    q = np.array([0.3, 1.0])
    polygons = reach.link_polygons(0, q)
    f = scene.fingers[0]
    elbow = f.p_W_base + f.l1 * np.array([np.cos(f.psi + q[0]), np.sin(f.psi + q[0])])
    direction = np.array([np.cos(f.psi + q.sum()), np.sin(f.psi + q.sum())])
    far_end = polygons[1][:2].mean(axis=0)
    np.testing.assert_allclose(far_end, elbow + 0.085 * direction, atol=1e-9)


@pytest.mark.parametrize("box", [(0.20, 0.10), (0.16, 0.08)])
def test_vectorized_closed_form_matches_the_scalar_one(box):
    from trajectotree.config import SceneConfig

    reach = Reachability(build_scene(SceneConfig(box_width=box[0], box_height=box[1])))
    rng = np.random.default_rng(5)
    reachable = 0
    for _ in range(60):
        pose = (rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), rng.uniform(-np.pi, np.pi))
        finger = int(rng.integers(NUM_FINGERS))
        arclengths = rng.uniform(0, reach.boundary.perimeter, 40)
        p_BC, n_B = reach.contacts(arclengths)
        for s, q, p, n in zip(arclengths, reach.closed_form_many(pose, finger, arclengths), p_BC, n_B):
            scalar = reach.closed_form(pose, finger, s)
            assert scalar.reachable == bool(np.isfinite(q[0]))
            if scalar.reachable:
                np.testing.assert_allclose(q, scalar.q, atol=1e-6)  # the scalar path rounds s to 1 nm
                reachable += 1
            np.testing.assert_allclose(np.array([p, n]), np.array(reach.boundary.point(s)), atol=1e-12)
    assert reachable > 100


def test_link_penetration_depths_match_scene_graph(scene):
    """physics.link_penetrations (planar separating axes) vs SceneGraph's signed distances between
    the link boxes and the box; deeper than the box's half depth, 3D separation is along z."""
    from trajectotree.planning.physics import link_penetrations

    rng = np.random.default_rng(5)
    depths, expected = [], []
    for _ in range(100):
        pose = np.array([rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), rng.uniform(-np.pi, np.pi)])
        q = np.concatenate([rng.uniform(f.q_lower, f.q_upper) for f in scene.fingers])
        depths.append(link_penetrations(pose[None], q[None], scene.fingers, scene.config.shape)[0])
        expected.append(np.maximum(-signed_distances(scene, pose, q), 0.0))
    depths, expected = np.array(depths), np.array(expected)
    planar = expected < 0.02
    assert 20 < np.sum(planar & (expected > 0)) and 20 < np.sum(expected == 0)
    np.testing.assert_allclose(depths[planar], expected[planar], atol=1e-6)
