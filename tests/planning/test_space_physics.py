"""The physics check in space (planning.physics.check_space_physics) on a hand-made static hold: three
fingertips of fingerpro4 on three faces of the cube (IK with the links clear), their forces from the
holding LP, the fourth finger away. It passes; it refuses the hold with one force turned out of its cone,
with one contact and fingertip moved 2 mm off the face, and with a link pushed into the cube; arrays that
do not fit are named."""

import re

import numpy as np
import pytest

from trajectotree.config import Config, mu_plan
from trajectotree.geometry import quaternion_matrices, so3_exp
from trajectotree.planning.physics import SpaceObjectModel, check_space_arrays, check_space_physics
from trajectotree.results import SPACE_GAP_TOL, SpaceTrajectory
from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.scene.statics import edge_wrenches_W, finger_torques, pyramid_edges
from trajectotree.search.spatial_reach import FingerIk
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

EDGES = 8
HOLDING = (0, 1, 2)  # fingers on +x, +y and -x (the fingers at 0, 90, 180 deg about z)
# m, in B: the pair on +-x off the centre line (y -1 cm), so that it needs the third finger on +y
CONTACTS_B = np.array([[0.0325, -0.01, -0.008], [0.0, 0.0325, -0.008], [-0.0325, -0.01, -0.008]])
NORMALS_B = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


@pytest.fixture(scope="module")
def hold():
    """(arrays of a 3-knot static hold, the object model, mu_plan)."""
    config = Config()
    mu = mu_plan(config.scene, config.search)
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    r = scene.tip_radius
    q = np.zeros((4, 3))
    for i, p_BC, n_B in zip(HOLDING, CONTACTS_B, NORMALS_B):
        solution = FingerIk(scene, i).solve(START_POSE, p_BC + r * n_B)
        assert solution is not None, f"finger {i} does not reach {p_BC}"
        q[i] = solution
    J = np.array([scene.fingers[i].jacobian(q[i], -r * n) for i, n in zip(HOLDING, NORMALS_B)])
    W = edge_wrenches_W(CONTACTS_B, NORMALS_B, mu, EDGES)
    tau_g = scene.gravity_torques(q)
    weight = scene.object.mass * scene.gravity
    torque, x = SpatialHoldingLp(3, EDGES, 3).solve(
        W, spatial_torque_rows(J, NORMALS_B, mu, EDGES), tau_g[list(HOLDING)], [0, 0, weight, 0, 0, 0]
    )
    assert torque <= 0.396
    f = np.zeros((4, 3))
    f[list(HOLDING)] = np.einsum("fm,fmc->fc", x.reshape(3, EDGES), pyramid_edges(NORMALS_B, mu, EDGES))
    tips = np.array([scene.fingers[i].fingertip(q[i]) for i in range(4)])
    p_W_C = tips.copy()
    p_W_C[list(HOLDING)] = CONTACTS_B
    tau = np.zeros((4, 3))
    tau[list(HOLDING)] = finger_torques(J, f[list(HOLDING)], tau_g[list(HOLDING)])
    tau[3] = tau_g[3]
    assert np.all(np.linalg.norm(f[list(HOLDING)], axis=1) > 0.1), "each of the three fingers holds"
    K = 3
    x_pose = np.tile(START_POSE, (K, 1))
    trajectory = SpaceTrajectory(
        t=np.linspace(0.0, 1.0, K),
        x=x_pose,
        v=np.zeros((K, 6)),
        q=np.tile(q.ravel(), (K, 1)),
        tau=np.tile(tau.ravel(), (K, 1)),
        f_W=np.tile(f, (K, 1, 1)),
        p_W_C=np.tile(p_W_C, (K, 1, 1)),
        p_W_tip=np.tile(tips, (K, 1, 1)),
        p_W_links=scene.link_ends_W(x_pose, np.tile(q.ravel(), (K, 1))),
    )
    capsules = scene.link_capsules()[0]
    box = SpaceObjectModel(
        size=scene.object.size,
        mass=scene.object.mass,
        inertia=scene.object.mass
        * np.diag([sum(np.square(scene.object.size)) - s * s for s in scene.object.size])
        / 12,
        gravity=scene.gravity,
        tip_radius=r,
        link_radii=tuple(c.radius for c in capsules),
    )
    return trajectory.arrays(), box, mu


def _changed(arrays, **new):
    return {**{k: np.array(v) for k, v in arrays.items()}, **new}


def test_a_static_hold_passes(hold):
    arrays, box, mu = hold
    check = check_space_physics(arrays, box, mu)
    assert check.passed, check.reason
    assert check.newton_euler_force_N <= 1e-9 and check.newton_euler_moment_Nm <= 1e-9
    assert check.friction_cone_N <= 1e-9
    assert check.penetration_m <= 1e-6 and check.link_penetration_m == 0.0
    assert check.to_json()["gap_tol_m"] == SPACE_GAP_TOL


def test_a_force_out_of_its_cone_is_refused(hold):
    arrays, box, mu = hold
    f = np.array(arrays["f_W"])
    n = np.array([1.0, 0.0, 0.0])  # finger 0 pushes on +x
    normal = -f[:, 0] @ n
    tangential = f[:, 0] + normal[:, None] * n
    direction = tangential / np.linalg.norm(tangential, axis=1, keepdims=True)
    f[:, 0] = -normal[:, None] * n + 1.2 * mu * normal[:, None] * direction  # 20 % beyond the cone's rim
    check = check_space_physics(_changed(arrays, f_W=f), box, mu)
    assert not check.passed
    assert check.friction_cone_N == pytest.approx(0.2 * mu * normal.max(), rel=1e-9)
    assert "friction cone violated" in check.reason


def test_a_contact_2mm_off_the_face_is_refused(hold):
    arrays, box, mu = hold
    p_W_C, tips = np.array(arrays["p_W_C"]), np.array(arrays["p_W_tip"])
    p_W_C[:, 1] += [0.0, 0.002, 0.0]  # finger 1 on +y, moved 2 mm out along the face's normal
    tips[:, 1] += [0.0, 0.002, 0.0]
    check = check_space_physics(_changed(arrays, p_W_C=p_W_C, p_W_tip=tips), box, mu)
    assert not check.passed
    assert check.force_at_distance_finger == 1
    assert check.force_at_distance_gap_m == pytest.approx(0.002, abs=2e-4)  # IK holds the tips to 0.1 mm
    assert re.search(r"finger 1 pushes the box with [\d.]+ N from 2\.[01]\d mm away", check.reason)


def test_a_link_inside_the_cube_is_refused(hold):
    arrays, box, mu = hold
    links = np.array(arrays["p_W_links"])
    links[:, 3, 2] = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.05]]  # finger 3's last link through the centre
    check = check_space_physics(_changed(arrays, p_W_links=links), box, mu)
    assert not check.passed and check.link_penetration_finger == 3
    assert check.link_penetration_m == pytest.approx(0.0325 + box.link_radii[2], abs=1e-6)


def test_a_turning_cube_follows_the_rule(hold):
    """A cube spinning up about z with no finger on it and no gravity: the moment-free rule's residual
    names the missing torque, and the kinematics of a pose off the rule are measured."""
    arrays, box, mu = hold
    K, h, w = 5, 0.1, np.array([0.0, 0.0, 1.0])
    R = np.array([so3_exp(w * h * k) for k in range(K)])
    quats = np.array([[np.cos(h * k / 2), 0.0, 0.0, np.sin(h * k / 2)] for k in range(K)])
    assert np.allclose(quaternion_matrices(quats), R)
    apart = 0.1 * np.outer(np.arange(4), [1.0, 0.0, 0.0])
    free = {
        "t": h * np.arange(K),
        "x": np.hstack([quats, np.zeros((K, 3))]),
        "v": np.tile(np.r_[w, 0.0, 0.0, 0.0], (K, 1)),
        "q": np.zeros((K, 12)),
        "tau": np.zeros((K, 12)),
        "f_W": np.zeros((K, 4, 3)),
        "p_W_C": np.tile([0.1, 0.1, 0.1], (K, 4, 1)),
        # the fingers 0.1 m apart along x, so that they do not overlap (the check's finger rule)
        "p_W_tip": np.tile([0.2, 0.2, 0.2], (K, 4, 1)) + apart,
        "p_W_links": np.tile([0.3, 0.3, 0.3], (K, 4, 3, 2, 1)) + apart[:, None, None],
    }
    weightless = SpaceObjectModel(**{**box.__dict__, "gravity": 0.0})
    check = check_space_physics(free, weightless, mu)
    assert check.passed, check.reason  # constant spin about a principal axis: no moment needed
    spun = _changed(free, v=free["v"] * np.linspace(1.0, 2.0, K)[:, None])
    check = check_space_physics(spun, weightless, mu)
    assert check.newton_euler_moment_Nm == pytest.approx(box.inertia[2, 2] * 0.25 / h, rel=1e-9)
    assert check.kinematics_rad > 1e-3 and "integration rule" in check.reason


@pytest.mark.parametrize(
    "name, shape, message",
    [
        ("x", (3, 3), "plan.npz x has shape (3, 3), expected (Kx7) with K = 3"),
        ("f_W", (3, 4, 2), "plan.npz f_W has shape (3, 4, 2)"),
        ("v", (2, 6), "plan.npz v has shape (2, 6), expected (Kx6) with K = 3"),
    ],
)
def test_arrays_that_do_not_fit_are_named(hold, name, shape, message):
    arrays, _, _ = hold
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        check_space_arrays(_changed(arrays, **{name: np.zeros(shape)}))


def test_rotation_helpers_against_scipy():
    from scipy.spatial.transform import Rotation

    from trajectotree.geometry import matrix_quaternions, so3_log

    r = Rotation.random(200, random_state=3)
    q = r.as_quat(scalar_first=True)
    assert np.allclose(quaternion_matrices(q), r.as_matrix(), atol=1e-12)
    assert np.allclose(so3_exp(r.as_rotvec()), r.as_matrix(), atol=1e-12)
    assert np.allclose(so3_log(r.as_matrix()), r.as_rotvec(), atol=1e-9)  # some within 4 deg of pi
    assert np.allclose(matrix_quaternions(r.as_matrix()), q * np.sign(q[:, :1]), atol=1e-9)
