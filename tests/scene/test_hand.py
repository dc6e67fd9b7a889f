"""Hands as data (trajectotree.scene.hand): each built-in description's kinematics against the
Drake plant built from the same model file, Drake's planar gripper against the welds of Drake's
own example (planar_gripper_common.cc, WeldGripperFrames), and the descriptions that must be
refused, each naming the finger, the joint or the file."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from pydrake.common import FindResourceOrThrow
from pydrake.geometry import QueryObject
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from trajectotree.config import HAND_NAMES, ConfigError, SceneConfig
from trajectotree.scene.hand import HandError, finger_bodies, hand_file, load_hand, with_hand_object
from trajectotree.scene.kinematics import TwoLinkFinger
from trajectotree.scene.plant import build_scene

GRIPPER_SDF = FindResourceOrThrow("drake/examples/planar_gripper/planar_gripper.sdf")


@pytest.fixture(scope="module", params=HAND_NAMES)
def scene(request):
    return build_scene(SceneConfig(hand=request.param))


def random_q(fingers, n, seed):
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(f.q_lower, f.q_upper, (n, 2)) for f in fingers], axis=1)


def test_descriptions_kinematics_match_the_plant_of_the_same_file(scene):
    """FK and the fingertip Jacobian of every finger, from the description's closed form and from
    the plant (tip frames at the fingertip spheres' centres), at random joint angles in and out of
    the limits, the object elsewhere."""
    fingers = scene.fingers
    hand = TwoLinkFinger.stack(fingers)
    n = scene.num_fingers
    qs = np.concatenate([random_q(fingers, 8, seed=0), np.random.default_rng(1).uniform(-3, 3, (8, n, 2))])
    plant, ctx = scene.plant, scene.plant.CreateDefaultContext()
    W = plant.world_frame()
    for q in qs:
        plant.SetPositions(ctx, scene.positions((0.01, -0.02, 0.3), q.ravel()))
        for i in range(n):
            frame = scene.tip_frame(i)
            p = plant.CalcPointsPositions(ctx, frame, np.zeros(3), W)[:, 0]
            J = plant.CalcJacobianTranslationalVelocity(ctx, JacobianWrtVariable.kV, frame, np.zeros(3), W, W)
            assert abs(p[2]) < 1e-12  # the fingertip stays in the planner's plane
            np.testing.assert_allclose(hand.fingertip(q)[i], p[:2], atol=1e-12)
            np.testing.assert_allclose(hand.jacobian(q)[i], J[:2, scene.hand_v_indices[2 * i : 2 * i + 2]], atol=1e-12)
            others = np.delete(J[:2, scene.hand_v_indices], [2 * i, 2 * i + 1], axis=1)
            assert np.all(others == 0)  # a finger's tip moves with its own joints only


def test_tip_spheres_and_link_boxes_are_the_plants_geometry(scene):
    """The fingertip radius and each link box's corners against SceneGraph's geometry poses."""
    plant, inspector = scene.plant, scene.scene_graph.model_inspector()
    context = scene.diagram.CreateDefaultContext()
    q = random_q(scene.fingers, 1, seed=3)[0]
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), scene.positions((0, 0, 0), q.ravel()))
    query = scene.scene_graph.get_query_output_port().Eval(scene.scene_graph.GetMyContextFromRoot(context))
    assert isinstance(query, QueryObject)
    for i, f in enumerate(scene.fingers):
        a1, a12 = f.angles(q[i])
        frames = ((f.p_W_base, a1), (f.elbow(q[i]), a12))
        for name, rect, (p_WJ, angle) in zip(f.link_bodies, f.link_boxes, frames):
            body = plant.GetBodyByName(name, scene.hand)
            boxes = [
                g for g in plant.GetCollisionGeometriesForBody(body) if type(inspector.GetShape(g)).__name__ == "Box"
            ]
            if rect is None:
                assert boxes == []
                continue
            (g,) = boxes
            X_WG = query.GetPoseInWorld(g)
            box = inspector.GetShape(g)
            half = np.array([box.width(), box.depth(), box.height()]) / 2
            signs = np.array([(a, b, c) for a in (1, -1) for b in (1, -1) for c in (1, -1)])
            corners = np.array([X_WG @ (half * s) for s in signs])  # the box straddles the plane: 4 pairs in x-y
            assert abs(X_WG.translation()[2]) < 1e-12  # centred on the plane
            expected = sorted({tuple(np.round(c[:2], 10)) for c in corners})
            got = sorted(tuple(np.round(c, 10)) for c in rect.corners(np.array(p_WJ), np.array(angle)))
            np.testing.assert_allclose(got, expected, atol=1e-12)
        tip = plant.GetBodyByName(f.link_bodies[1], scene.hand)
        spheres = [
            inspector.GetShape(g).radius()
            for b in plant.GetBodiesWeldedTo(tip)
            for g in plant.GetCollisionGeometriesForBody(b)
            if type(inspector.GetShape(g)).__name__ == "Sphere"
        ]
        assert spheres == [f.tip_radius] == [scene.tip_radius]


def test_a_fingers_bodies_end_with_the_one_that_carries_its_fingertip_sphere(scene):
    """finger_bodies: the two links, and Drake's gripper's tip link (welded to link 2) after them;
    the last body holds the fingertip sphere's collision geometry, of the description's radius."""
    plant, inspector = scene.plant, scene.scene_graph.model_inspector()
    for f in scene.fingers:
        bodies = finger_bodies(plant, scene.hand, f)
        assert [b.name() for b in bodies[:2]] == list(f.link_bodies)
        assert len(bodies) == (3 if scene.config.hand == "drake_planar_gripper" else 2)
        spheres = [
            inspector.GetShape(g).radius()
            for g in plant.GetCollisionGeometriesForBody(bodies[-1])
            if type(inspector.GetShape(g)).__name__ == "Sphere"
        ]
        assert spheres == [f.tip_radius]


def test_each_hand_collision_has_the_scenes_friction():
    for name in HAND_NAMES:
        scene = build_scene(SceneConfig(hand=name, mu=0.55))
        inspector = scene.scene_graph.model_inspector()
        for b in scene.plant.GetBodyIndices(scene.hand):
            for g in scene.plant.GetCollisionGeometriesForBody(scene.plant.get_body(b)):
                friction = inspector.GetProximityProperties(g).GetProperty("material", "coulomb_friction")
                assert (friction.static_friction(), friction.dynamic_friction()) == (0.55, 0.55), name


def test_the_project_hand_is_four_identical_fingers_on_a_circle():
    hand = load_hand("planar_hand")
    assert hand.num_fingers == 4 and hand.tip_radius == 0.01
    for i, f in enumerate(hand.fingers):
        np.testing.assert_allclose(np.linalg.norm(f.p_W_base), 0.22, atol=1e-6)
        np.testing.assert_allclose(
            f.p_W_base, 0.22 * np.array([math.cos(a := math.radians(-45 + 90 * i)), math.sin(a)]), atol=1e-6
        )
        np.testing.assert_allclose(np.remainder(f.psi - a, 2 * math.pi), math.pi, atol=1e-6)  # q1 = 0: at the origin
        assert (f.l1, f.l2) == pytest.approx((0.1, 0.1)) and np.all(f.tau_max == 1.0)
        assert f.joints == (f"finger{i}_joint1", f"finger{i}_joint2") and f.tip_frame == f"finger{i}_tip"


def drake_example_gripper():
    """Drake's planar gripper as its example builds it: the model frame is the world, the finger
    bases welded at Rx(angle) * translation(0, 0, 0.201), gravity along -z."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    Parser(plant).AddModels(GRIPPER_SDF)
    for k, angle in enumerate((math.pi / 3, -math.pi / 3, math.pi), start=1):
        X_GF = RigidTransform(RotationMatrix.MakeXRotation(angle)) @ RigidTransform(np.array([0, 0, 0.201]))
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(f"finger{k}_base"), X_GF)
    plant.Finalize()
    return builder.Build(), plant, scene_graph


def test_the_drake_gripper_matches_drakes_own_example():
    """Description: 3 fingers in the y-z plane (links 0.085 m and 0.0713 m to the 15 mm sphere,
    75 N m, +-1.57 rad); its fingertips equal the sphere centres of Drake's example, whose frame
    is mapped by the plane (y, z) -> (x, y), at random joint angles."""
    hand = load_hand("drake_planar_gripper")
    assert hand.num_fingers == 3 and hand.tip_radius == 0.015
    np.testing.assert_array_equal(hand.R_WM, [[0, 1, 0], [0, 0, 1], [1, 0, 0]])
    for f in hand.fingers:
        assert (f.l1, f.l2) == pytest.approx((0.085, 0.13 + 0.0263 - 0.085))
        np.testing.assert_allclose(np.linalg.norm(f.p_W_base), 0.201, atol=1e-12)
        assert np.all(f.tau_max == 75.0) and np.all(f.q_lower == -1.57) and np.all(f.q_upper == 1.57)
        assert f.link_boxes[0] is None and f.link_boxes[1] is not None  # Drake's link 1 has no collision geometry
    diagram, plant, scene_graph = drake_example_gripper()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    inspector = scene_graph.model_inspector()
    stack = TwoLinkFinger.stack(hand.fingers)
    for q in random_q(hand.fingers, 6, seed=4):
        for i, f in enumerate(hand.fingers):
            for name, value in zip(f.joints, q[i]):
                plant.GetJointByName(name).set_angle(plant_context, value)
        query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
        for i in range(hand.num_fingers):
            tip = plant.GetBodyByName(f"finger{i + 1}_tip_link")
            (sphere,) = [
                g for g in plant.GetCollisionGeometriesForBody(tip) if type(inspector.GetShape(g)).__name__ == "Sphere"
            ]
            p_G = query.GetPoseInWorld(sphere).translation()
            np.testing.assert_allclose(hand.R_WM @ p_G, [*stack.fingertip(q)[i], 0.0], atol=1e-12)


# -- descriptions that must be refused ------------------------------------------------------------------
def write_hand(tmp_path, fingers, model=GRIPPER_SDF, name="hand.yaml", welds=None) -> Path:
    """A copy of the gripper's YAML with `fingers` (and `welds`) replaced."""
    text = Path(hand_file("drake_planar_gripper").source).read_text()
    head = text[: text.index("welds:")]
    welds = (
        welds if welds is not None else text[text.index("welds:") : text.index("fingers:")]  # Drake's three welds
    )
    path = tmp_path / name
    path.write_text(
        head.replace("package://drake/examples/planar_gripper/planar_gripper.sdf", str(model)) + welds + fingers
    )
    return path


GOOD = [
    "{joints: [finger1_BaseJoint, finger1_MidJoint], tip: finger1_tip_link, tip_xyz: [0, 0, -0.0263]}",
    "{joints: [finger2_BaseJoint, finger2_MidJoint], tip: finger2_tip_link, tip_xyz: [0, 0, -0.0263]}",
    "{joints: [finger3_BaseJoint, finger3_MidJoint], tip: finger3_tip_link, tip_xyz: [0, 0, -0.0263]}",
]


def fingers_text(entries) -> str:
    return "fingers:\n" + "".join(f"  - {e}\n" for e in entries)


def test_a_copy_of_the_gripper_yaml_reads_as_the_builtin(tmp_path):
    path = write_hand(tmp_path, fingers_text(GOOD))
    mine, builtin = load_hand(str(path)), load_hand("drake_planar_gripper")
    for a, b in zip(mine.fingers, builtin.fingers):
        np.testing.assert_array_equal(a.p_W_base, b.p_W_base)
        assert (a.psi, a.l1, a.l2, a.joints) == (b.psi, b.l1, b.l2, b.joints)


@pytest.mark.parametrize(
    "entries, expected",
    [
        (
            [GOOD[0], GOOD[1].replace("finger2_MidJoint", "finger2_KneeJoint"), GOOD[2]],
            "finger 1: its model .*planar_gripper.sdf has no joint 'finger2_KneeJoint'",
        ),
        ([GOOD[0], "{joints: [finger2_BaseJoint], tip: finger2_tip_link}", GOOD[2]], r"finger 1 has 1 joint\(s\)"),
        (GOOD[:2], r"names 2 finger\(s\); a hand needs at least 3"),
        (
            [
                GOOD[0],
                GOOD[1],
                GOOD[2].replace("finger3_BaseJoint, finger3_MidJoint", "finger3_MidJoint, finger3_BaseJoint"),
            ],
            "finger 2: joint 'finger3_BaseJoint' does not follow joint 'finger3_MidJoint'",
        ),
        (
            [GOOD[0], GOOD[1], GOOD[2].replace("finger3_tip_link,", "finger3_nail,")],
            "finger 2: .* no frame or body 'finger3_nail'",
        ),
        (
            [GOOD[0], GOOD[1], GOOD[2].replace("-0.0263", "-0.03")],
            "finger 2: 0 collision spheres are centred at its tip",
        ),
    ],
)
def test_bad_descriptions_name_the_finger_the_joint_and_the_file(tmp_path, entries, expected):
    path = write_hand(tmp_path, fingers_text(entries))
    with pytest.raises(HandError, match=f"hand {path}: {expected}"):
        load_hand(str(path))


def test_a_plane_the_joints_do_not_turn_in_is_refused(tmp_path):
    """Drake's gripper read in the x-y plane (its joints turn about x): named joint, refused."""
    path = write_hand(tmp_path, fingers_text(GOOD))
    path.write_text(
        path.read_text()
        .replace("x_axis: [0, 1, 0]", "x_axis: [1, 0, 0]")
        .replace("y_axis: [0, 0, 1]", "y_axis: [0, 1, 0]")
    )
    with pytest.raises(HandError, match="finger 0: joint 'finger1_BaseJoint' turns about .* not \\+z"):
        load_hand(str(path))


def test_a_model_without_its_yaml_and_unknown_names_are_refused(tmp_path):
    model = tmp_path / "hand.sdf"
    model.write_text(Path(GRIPPER_SDF).read_text())
    with pytest.raises(HandError, match=f"hand {model}: has no description beside it: write {tmp_path / 'hand.yaml'}"):
        hand_file(str(model))
    for bad in ("four_finger_hand", str(tmp_path / "missing.yaml"), 3):
        with pytest.raises(ConfigError, match="scene.hand = .*; valid: planar_hand, drake_planar_gripper"):
            SceneConfig(hand=bad)
    (tmp_path / "hand.yaml").write_text(fingers_text(GOOD))  # model: omitted, so the SDF beside it
    with pytest.raises(HandError, match="finger 0: its base 'finger1_base' .* is free in the model; weld it"):
        load_hand(str(model))
    assert dataclasses.replace(SceneConfig(), hand=str(model)).hand == str(model)


def test_the_gripper_yamls_object_is_drakes_brick_as_its_sdf_reads():
    """The brick the gripper's YAML names (with_hand_object's defaults) against planar_brick.sdf
    parsed by Drake: its collision box in the hand's plane, its mass, its inertia about the axis
    normal to the plane, and the friction Drake's parser gives it (the SDF names none)."""
    own = hand_file("drake_planar_gripper").object
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
    Parser(plant).AddModels(FindResourceOrThrow("drake/examples/planar_gripper/planar_brick.sdf"))
    plant.Finalize()
    body = plant.GetBodyByName("brick_link")
    R_WM = hand_file("drake_planar_gripper").R_WM
    inspector = scene_graph.model_inspector()
    boxes = [g for g in plant.GetCollisionGeometriesForBody(body) if inspector.GetShape(g).__class__.__name__ == "Box"]
    assert len(boxes) == 1
    size_W = np.abs(R_WM @ inspector.GetShape(boxes[0]).size())
    np.testing.assert_allclose(own.size, size_W[:2])
    assert own.mass == body.default_mass()
    I_W = R_WM @ body.default_rotational_inertia().CopyToFullMatrix3() @ R_WM.T
    assert own.inertia == pytest.approx(I_W[2, 2], rel=1e-12)
    friction = inspector.GetProximityProperties(boxes[0]).GetProperty("material", "coulomb_friction")
    assert own.mu == friction.static_friction() == friction.dynamic_friction()


def test_the_hands_object_fills_only_what_the_user_left_unset():
    """with_hand_object: the brick for a bare SceneConfig, a given shape keeps the brick's mass and
    friction but not its inertia, a given mass scales it; a hand without an object is unchanged."""
    bare = with_hand_object(SceneConfig(hand="drake_planar_gripper"))
    assert (bare.box_width, bare.box_height, bare.box_mass, bare.mu, bare.object_inertia) == (
        0.1,
        0.1,
        0.028,
        1.0,
        1.17e-5,
    )
    box = with_hand_object(SceneConfig(hand="drake_planar_gripper", box_width=0.12), {"box_width"})
    assert (box.box_width, box.box_height, box.box_mass, box.object_inertia) == (0.12, 0.1, 0.028, None)
    heavy = with_hand_object(SceneConfig(hand="drake_planar_gripper", box_mass=0.056, mu=0.5), {"box_mass", "mu"})
    assert (heavy.box_mass, heavy.mu) == (0.056, 0.5) and heavy.object_inertia == pytest.approx(2.34e-5)
    assert with_hand_object(SceneConfig()) == SceneConfig()
