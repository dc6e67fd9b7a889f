"""The plant built from the SDF models: kinematics, Jacobians, physical parameters."""

import numpy as np
import pytest

from trajectotree.config import ConfigError, ObjectConfig, SceneConfig
from trajectotree.scene.plant import NUM_FINGERS, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def closed_form_tip(base, psi, l1, l2, q):
    """Independent 2-link planar forward kinematics."""
    return (
        np.asarray(base)
        + l1 * np.array([np.cos(psi + q[0]), np.sin(psi + q[0])])
        + l2 * np.array([np.cos(psi + q[0] + q[1]), np.sin(psi + q[0] + q[1])])
    )


def test_fingertips_match_closed_form_kinematics(scene):
    # The model's documented geometry: bases on a 0.22 m circle at -45 + 90 i degrees,
    # pointing at the origin, links of 0.10 m.
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-1.5, 1.5, 8)
        p_WF = scene.fingertip_positions(q)
        for i in range(NUM_FINGERS):
            angle = np.deg2rad(-45 + 90 * i)
            base = 0.22 * np.array([np.cos(angle), np.sin(angle)])
            expected = closed_form_tip(base, angle + np.pi, 0.10, 0.10, q[2 * i : 2 * i + 2])
            np.testing.assert_allclose(p_WF[i], expected, atol=1e-6)
            np.testing.assert_allclose(scene.fingers[i].fingertip(q[2 * i : 2 * i + 2]), expected, atol=1e-6)


def test_fingertip_jacobians_match_finite_differences(scene):
    rng = np.random.default_rng(1)
    q = rng.uniform(-1.0, 1.0, 8)
    J = scene.fingertip_jacobians(q)
    eps = 1e-6
    for j in range(8):
        dq = np.zeros(8)
        dq[j] = eps
        fd = (scene.fingertip_positions(q + dq) - scene.fingertip_positions(q - dq)) / (2 * eps)
        np.testing.assert_allclose(J[:, :, j], fd, atol=1e-8)
    for i in range(NUM_FINGERS):  # the closed-form Jacobian agrees with the plant
        np.testing.assert_allclose(
            scene.fingers[i].jacobian(q[2 * i : 2 * i + 2]), J[i][:, 2 * i : 2 * i + 2], atol=1e-9
        )
        np.testing.assert_allclose(J[i][:, np.r_[0 : 2 * i, 2 * i + 2 : 8]], 0.0)  # fingers are independent


def test_gravity_points_down_y(scene):
    np.testing.assert_allclose(scene.plant.gravity_field().gravity_vector(), [0, -9.81, 0])


def box_parameters(scene):
    body = scene.plant.GetBodyByName("box", scene.box)
    inertia = body.default_spatial_inertia()
    inspector = scene.scene_graph.model_inspector()
    (gid,) = scene.plant.GetCollisionGeometriesForBody(body)
    shape = inspector.GetShape(gid)
    mu = inspector.GetProximityProperties(gid).GetProperty("material", "coulomb_friction").static_friction()
    izz = inertia.CalcRotationalInertia().get_moments()[2]
    return body.default_mass(), izz, (shape.width(), shape.depth()), mu


@pytest.mark.parametrize("config", [SceneConfig(), SceneConfig(box_width=0.16, box_height=0.08, box_mass=0.12, mu=0.4)])
def test_box_parameters_follow_the_config(config):
    scene = build_scene(config)
    mass, izz, size, mu = box_parameters(scene)
    assert mass == pytest.approx(config.box_mass)
    assert izz == pytest.approx(config.box_mass * (config.box_width**2 + config.box_height**2) / 12)
    assert size == pytest.approx((config.box_width, config.box_height))
    assert mu == pytest.approx(config.mu)
    # the fingers carry the same friction, so Drake's combined coefficient is mu
    inspector = scene.scene_graph.model_inspector()
    hand_mu = [
        inspector.GetProximityProperties(g).GetProperty("material", "coulomb_friction").static_friction()
        for b in scene.plant.GetBodyIndices(scene.hand)
        for g in scene.plant.GetCollisionGeometriesForBody(scene.plant.get_body(b))
    ]
    assert len(hand_mu) == 12 and hand_mu == pytest.approx([config.mu] * 12)


def test_planar_joint_moves_box_in_plane(scene):
    ctx = scene.plant.CreateDefaultContext()
    scene.plant.SetPositions(ctx, scene.positions((0.01, -0.02, 0.3), np.zeros(8)))
    X_WB = scene.plant.GetBodyByName("box", scene.box).EvalPoseInWorld(ctx)
    np.testing.assert_allclose(X_WB.translation(), [0.01, -0.02, 0.0], atol=1e-12)
    np.testing.assert_allclose(X_WB.rotation().ToRollPitchYaw().vector(), [0, 0, 0.3], atol=1e-12)


HEXAGON = ObjectConfig(vertices=tuple((0.06 * np.cos(a), 0.06 * np.sin(a)) for a in np.arange(6) * np.pi / 3))


@pytest.mark.parametrize("object_config", [ObjectConfig(), HEXAGON])
def test_an_object_inertia_reaches_the_plant_the_check_the_cito_model_and_the_controller(object_config):
    """scene.object_inertia (Drake's brick's 1.17e-5 kg m^2, not a uniform plate's) is the plant body's
    I_zz, the physics check's and CITO's inertia, and the grasp controller's (scaled by an estimated mass)."""
    from trajectotree.cito.knot import BodyParams
    from trajectotree.planning.physics import ObjectModel

    config = SceneConfig(box_width=0.1, box_height=0.1, box_mass=0.028, object_inertia=1.17e-5, object=object_config)
    scene = build_scene(config)
    body = scene.plant.GetBodyByName("box", scene.box)
    izz = body.default_spatial_inertia().CalcRotationalInertia().CopyToFullMatrix3()[2, 2]
    assert izz == pytest.approx(1.17e-5, rel=1e-12)
    assert ObjectModel.from_scene(scene).inertia == 1.17e-5
    assert BodyParams(scene, 100.0, mu=0.7).inertia == 1.17e-5
    assert config.inertia_zz(0.056) == pytest.approx(2.34e-5)
    assert SceneConfig().inertia_zz() == SceneConfig().shape.inertia(0.05)


def test_an_object_inertia_no_body_can_have_is_refused():
    """I_zz must satisfy the triangle inequality with the prism's other moments (Drake's parser would
    replace the whole inertia): Drake's brick's 1.17e-5 is fine for its 0.1 x 0.1 m, not for a 0.2 x 0.1 m box."""
    with pytest.raises(ConfigError, match=r"scene.object_inertia = 1.17e-05 .*triangle inequality.*\[7e-05, "):
        SceneConfig(box_mass=0.028, object_inertia=1.17e-5)
