"""Algorithm 1 in space (search.space_tree) and its reach (search.spatial_reach.SpatialReach) on
fingerpro4: the geodesic path, IK reach against Drake's own kinematics and signed distances, a 90 deg
goal about a horizontal axis planned with every node re-checked, and the search command's goals."""

import json
import math

import numpy as np
import pytest
from conftest import holding_torque
from pydrake.math import RollPitchYaw

from trajectotree.cli import main
from trajectotree.config import Config, mu_plan
from trajectotree.geometry import BOX_FACE_NAMES, BOX_FACE_NORMALS, box_face_grid, quaternion_angle
from trajectotree.refusal import RefusalKind
from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.search.grasp import SpatialClosure
from trajectotree.search.space_tree import SPACE_MAX_SEGMENT_ROTATION, space_object_path
from trajectotree.search.spatial_reach import CLEARANCE, SpatialReach, box_transform

QUARTER_ABOUT_X = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])
EDGES = 8


@pytest.fixture(scope="module")
def scene():
    config = Config()
    return build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)


def _distances(scene, pose, q):
    """Drake's signed distances (pairs within 5 cm) with the box at `pose` and the fingers at q (F, n), each
    as (the finger of A or None for the box, A is a fingertip sphere, the same for B, distance)."""
    plant, inspector = scene.plant, scene.scene_graph.model_inspector()
    context = scene.diagram.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), scene.positions(pose, q))
    query = scene.scene_graph.get_query_output_port().Eval(scene.scene_graph.GetMyContextFromRoot(context))
    body_finger = {
        plant.GetJointByName(n, scene.hand).child_body().index(): i
        for i, f in enumerate(scene.hand_file.fingers)
        for n in f.joints
    }

    def owner(g):
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(g)).index()
        return body_finger.get(body), inspector.GetShape(g).__class__.__name__ == "Sphere"

    return [
        (*owner(p.id_A), *owner(p.id_B), p.distance) for p in query.ComputeSignedDistancePairwiseClosestPoints(0.05)
    ]


def _tip(scene, pose, q, finger):
    plant = scene.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, scene.positions(pose, q))
    return scene.tip_frame(finger).CalcPoseInWorld(context).translation()


def test_the_path_is_the_geodesic_in_segments_of_at_most_the_largest_rotation():
    path = space_object_path(QUARTER_ABOUT_X)
    assert len(path) == 6  # 90 deg in 5 segments of 18 deg (at most 20 deg each)
    np.testing.assert_allclose(path[0], START_POSE)
    np.testing.assert_allclose(path[-1][:4], QUARTER_ABOUT_X, atol=1e-12)
    steps = [quaternion_angle(a[:4], b[:4]) for a, b in zip(path[:-1], path[1:])]
    np.testing.assert_allclose(steps, math.radians(18.0), atol=1e-9)
    np.testing.assert_allclose(path[:, 4:], 0.0)  # the cube's position is kept
    assert len(space_object_path(-QUARTER_ABOUT_X)) == 6  # -q is the same rotation: the shorter way
    assert len(space_object_path([0.0, 0.0, 0.0, 1.0])) == math.ceil(math.pi / SPACE_MAX_SEGMENT_ROTATION) + 1


def test_reach_puts_the_fingertip_on_the_contact_with_the_links_clear_of_the_cube(scene):
    reach = SpatialReach(scene)
    p_BC, n_B = box_face_grid(scene.object.half, 3, scene.tip_radius)
    pose = np.r_[RollPitchYaw(0.4, -0.3, 0.2).ToQuaternion().wxyz(), 0.0, 0.0, 0.0]
    X_WB = box_transform(pose)
    solved = 0
    for finger in range(scene.num_fingers):
        for face in range(6):
            p_BF = p_BC[face, 4] + scene.tip_radius * n_B[face]  # each face's centre
            result = reach.solve(pose, finger, p_BF)
            if not result.reachable:
                assert result.refusal.kind in (
                    RefusalKind.OUT_OF_REACH,
                    RefusalKind.IK_FAILED,
                    RefusalKind.LINKS_PENETRATE,
                )
                continue
            solved += 1
            q = np.zeros((scene.num_fingers, 3))
            q[finger] = result.q
            np.testing.assert_allclose(_tip(scene, pose, q, finger), X_WB @ p_BF, atol=2e-4)
            f = scene.fingers[finger]
            assert np.all(result.q >= f.q_lower - 1e-9) and np.all(result.q <= f.q_upper + 1e-9)
            for a, a_tip, b, b_tip, d in _distances(scene, pose, q):
                if {a, b} == {finger, None} and not (a_tip or b_tip):  # this finger's links and the cube
                    assert d >= CLEARANCE - 1e-5
    assert 6 <= solved < 24  # some faces, not every face by every finger


def test_reach_refuses_a_target_beyond_the_workspace_before_any_ik(scene):
    reach = SpatialReach(scene)
    result = reach.solve(START_POSE, 0, [0.0, 0.0, -1.0])  # a metre below the cube
    assert result.refusal.kind is RefusalKind.OUT_OF_REACH and reach.ik_calls == 0


def test_two_fingers_on_one_point_collide(scene):
    reach = SpatialReach(scene)
    target = np.array([0.06, 0.06, 0.04])  # beside the cube, between fingers 0 and 1
    q = np.zeros((scene.num_fingers, 3))
    for i in (0, 1):
        nearest = reach.workspaces[i].nearest(target, 1)[1][0]
        q[i] = reach.programs[i].solve(False, START_POSE, target, [reach.workspaces[i].q[nearest]])
    clash = reach.links_clear(START_POSE, q)
    assert clash.kind is RefusalKind.FINGERS_COLLIDE and set(clash.fingers) == {0, 1}


def test_a_quarter_turn_about_a_horizontal_axis_plans_and_every_node_checks(scene, quarter_turn):
    config = Config()
    mu = mu_plan(config.scene, config.search)
    plan = quarter_turn(config.search)  # conftest's: searched once per process
    assert plan.success, plan.reason
    nodes = plan.nodes
    np.testing.assert_allclose(nodes[-1].object_pose[:4], QUARTER_ABOUT_X, atol=1e-12)
    closure = SpatialClosure(mu, half_size=float(max(scene.object.half)))
    for k, node in enumerate(nodes):
        n_B = BOX_FACE_NORMALS[[BOX_FACE_NAMES.index(f) for f in node.faces]]
        X_WB = box_transform(node.object_pose)
        assert closure.check(node.p_BC, n_B).in_closure
        for i in range(scene.num_fingers):  # each fingertip sphere touches its contact
            np.testing.assert_allclose(
                _tip(scene, node.object_pose, node.q, i), X_WB @ (node.p_BC[i] + scene.tip_radius * n_B[i]), atol=2e-4
            )
        for a, a_tip, b, b_tip, d in _distances(scene, node.object_pose, node.q):
            if a is not None and b is not None and a != b:
                assert d >= CLEARANCE - 1e-5  # fingers apart
            elif (a is None) != (b is None) and not (a_tip or b_tip):
                assert d >= CLEARANCE - 1e-5  # links clear of the cube
        if k == 0:
            continue
        previous = nodes[k - 1]
        moved = [i for i in range(4) if not np.array_equal(node.p_BC[i], previous.p_BC[i])]
        assert moved == ([] if node.switching_finger is None else [node.switching_finger])
        stance = [i for i in range(4) if i != node.switching_finger]
        for end in (previous, node):  # the holding fingers carry the cube within the motors at both ends
            torque = holding_torque(scene, end.object_pose, end.p_BC[stance], n_B[stance], end.q[stance], stance, mu)
            assert torque <= 0.396 + 1e-9
            assert node.stance_torque >= torque - 1e-6


def test_the_search_command_prints_the_sequence_as_json(capsys):
    assert main(["search", "--hand", "fingerpro4", "--goal-rpy", str(math.pi / 2), "0", "0", "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["kind"] == "space" and plan["success"]
    np.testing.assert_allclose(plan["goal_quaternion"], QUARTER_ABOUT_X, atol=1e-12)
    nodes = plan["contact_sequence"]
    assert len(nodes) == 6 and nodes[0]["switching_finger"] is None
    for node in nodes:
        assert len(node["object_pose"]) == 7 and np.array(node["q"]).shape == (4, 3)
        assert all(c["face"] in BOX_FACE_NAMES and len(c["p_BC"]) == 3 for c in node["contacts"])


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hand", "fingerpro4", "--goal-quat", "0", "0", "0", "0"], "--goal-quat = [0.0, 0.0, 0.0, 0.0] has norm 0"),
        (["--hand", "fingerpro4", "--goal-quat", "1", "nan", "0", "0"], "--goal-quat[1] = nan is not a finite number"),
        (["--hand", "fingerpro4", "--goal-rpy", "0", "inf", "0"], "--goal-rpy[1] = inf is not a finite number"),
        (["--goal-quat", "1", "0", "0", "0"], "--goal-quat = [1.0, 0.0, 0.0, 0.0] takes a hand in space"),
        (["--hand", "drake_planar_gripper", "--goal-rpy", "0", "0", "1"], "the hand 'drake_planar_gripper' is planar"),
        (["--hand", "fingerpro4", "--goal", "0.3"], "--goal = 0.3 is a planar goal"),
        (["--hand", "fingerpro4"], "no goal: give --goal-quat W X Y Z or --goal-rpy R P Y"),
    ],
)
def test_the_search_command_refuses_a_bad_goal_in_one_line(tmp_path, capsys, argv, message):
    figure = tmp_path / "f.png"
    assert main(["search", *argv, "--figure", str(figure)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert not figure.exists()
