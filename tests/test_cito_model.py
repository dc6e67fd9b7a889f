"""The CITO model against independent references: the plant's mass matrix, gravity
and kinematics, the exact box distance, and finite differences of the Jacobian."""

import numpy as np
import pytest

from trajectotree.cito.contact import FACE_NORMALS, face_offsets, smooth_distance, smooth_normal
from trajectotree.cito.hand import HandModel
from trajectotree.cito.knot import BodyParams, KnotRows
from trajectotree.cito.variables import KNOT_SIZE, SLICES
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene import NUM_FINGERS, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


@pytest.fixture(scope="module")
def hand(scene):
    return HandModel.from_scene(scene)


def test_hand_dynamics_match_the_plant(scene, hand):
    plant, ctx = scene.plant, scene.plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    iv = scene.hand_v_indices
    for _ in range(5):
        q = rng.uniform(-1.2, 1.2, 8)
        plant.SetPositions(ctx, scene.positions((0.01, -0.02, 0.3), q))
        M_plant = plant.CalcMassMatrix(ctx)[np.ix_(iv, iv)]
        M = np.zeros((8, 8))
        for i, block in enumerate(hand.mass_matrices(q)):
            M[2 * i:2 * i + 2, 2 * i:2 * i + 2] = block
        np.testing.assert_allclose(M, M_plant, atol=1e-12)
        np.testing.assert_allclose(hand.gravity_forces(q).ravel(), plant.CalcGravityGeneralizedForces(ctx)[iv], atol=1e-12)
        np.testing.assert_allclose(hand.fingertips(q), scene.fingertip_positions(q), atol=1e-9)
        J_plant = scene.fingertip_jacobians(q)
        J = hand.jacobians(q)
        for i in range(NUM_FINGERS):
            np.testing.assert_allclose(J[i], J_plant[i][:, 2 * i:2 * i + 2], atol=1e-9)


def test_hand_ik_inverts_the_kinematics(hand):
    q = np.array([0.3, 1.2, -0.2, 0.9, 0.1, 1.5, -0.4, 0.7])
    tips = hand.fingertips(q)
    for i in range(NUM_FINGERS):
        np.testing.assert_allclose(hand.ik(i, tips[i]), q[2 * i:2 * i + 2], atol=1e-9)
    assert hand.ik(0, hand.fingers.p_W_base[0] + [0.5, 0.0]) is None  # out of reach
    # Many targets at once (the guess's path): each row bit for bit the one-target IK, NaN for None.
    targets = np.array([tips[0], tips[0] + [0.01, -0.02], hand.fingers.p_W_base[0] + [0.5, 0.0], tips[0] - 0.01])
    many = hand.ik_many(0, targets)
    for p, row in zip(targets, many):
        one = hand.ik(0, p)
        assert np.all(np.isnan(row)) if one is None else row.tobytes() == one.tobytes()
    assert np.isnan(many[2]).all()


def test_smooth_distance_matches_the_exact_distance_away_from_corners():
    box = ConvexPolygon.box(0.20, 0.10)
    offsets = face_offsets(0.20, 0.10)
    rng = np.random.default_rng(1)
    s = rng.uniform(0, box.perimeter, 400)
    s = s[[box.corner_distance(si) > 0.015 for si in s]]          # the search's corner margin
    for lift in (0.0, 0.01, 0.03):                                  # on the surface, tip centres, further out
        pts = np.array([box.point(si)[0] + lift * box.point(si)[1] for si in s])
        normals = np.array([box.point(si)[1] for si in s])
        phi, grad, hess = smooth_distance(pts, offsets, 200.0)
        exact = np.array([box.signed_distance(p) for p in pts])
        assert np.all(phi >= exact - 1e-12)                          # log-sum-exp over-estimates the max
        # Bound: log(1 + exp(-k * 0.015)) / k = 0.24 mm on the surface 15 mm from a corner.
        np.testing.assert_allclose(phi, exact, atol=2.5e-4)
        n, _ = smooth_normal(grad, hess)
        np.testing.assert_allclose(n, normals, atol=0.05)
    # At face centres the error is below a micrometre, and at a corner at most log(4)/k.
    centres = np.array([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.0], [0.0, -0.05]])
    np.testing.assert_allclose(smooth_distance(centres, offsets, 200.0)[0], 0.0, atol=1e-6)
    assert 0.0 < smooth_distance(np.array([[0.1, 0.05]]), offsets, 200.0)[0][0] <= np.log(4) / 200.0 + 1e-12
    assert np.allclose(FACE_NORMALS @ [1.0, 0.0], [1, 0, -1, 0])


def test_smooth_normal_jacobian_matches_finite_differences():
    offsets = face_offsets(0.20, 0.10)
    p = np.array([[0.105, 0.03], [0.09, 0.06], [-0.02, -0.07]])
    _, grad, hess = smooth_distance(p, offsets, 200.0)
    n, dn = smooth_normal(grad, hess)
    h = 1e-7
    for j in range(2):
        dp = np.zeros(2)
        dp[j] = h
        n_plus = smooth_normal(*smooth_distance(p + dp, offsets, 200.0)[1:])[0]
        n_minus = smooth_normal(*smooth_distance(p - dp, offsets, 200.0)[1:])[0]
        np.testing.assert_allclose(dn[:, :, j], (n_plus - n_minus) / (2 * h), atol=1e-5)


@pytest.fixture(scope="module")
def rows(scene):
    rng = np.random.default_rng(2)
    pinned = np.array([[1, 1, 1, 1], [0, 0, 0, 0], [1, 0, 1, 0], [0, 1, 1, 1]], bool)
    normals = np.tile(np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]]), (4, 1, 1))
    return KnotRows(BodyParams(scene, 200.0, mu=scene.config.mu), pinned, rng.uniform(-0.1, 0.1, (4, 4, 2)), normals)


def random_knots(n, seed=3):
    rng = np.random.default_rng(seed)
    Z = rng.uniform(-1, 1, (n, KNOT_SIZE))
    Z[:, SLICES["x"]][:, :2] *= 0.05                 # object positions within 5 cm
    return Z


def test_knot_jacobian_matches_finite_differences(rows):
    Z = random_knots(4)
    val, jac = rows.evaluate(Z, True)
    h = 1e-6
    for k in range(4):
        fd = np.zeros((val.shape[1], KNOT_SIZE))
        for j in range(KNOT_SIZE):
            dZ = np.zeros_like(Z)
            dZ[k, j] = h
            fd[:, j] = (rows.evaluate(Z + dZ, False)[0][k] - rows.evaluate(Z - dZ, False)[0][k]) / (2 * h)
        scale = np.maximum(1.0, np.abs(fd))
        assert np.max(np.abs(jac[k] - fd) / scale) < 1e-6, f"knot {k}"


def test_one_knot_paths_agree_with_the_batch(rows):
    Z = random_knots(4, seed=4)
    val, jac = rows.evaluate(Z, True)
    for k in range(4):
        one = rows.knot(k)
        n = one.num_rows[0]
        np.testing.assert_allclose(one.values_one(Z[k]), val[k, :n], atol=1e-12)
        v1, j1 = one.evaluate(Z[k:k + 1], True)
        np.testing.assert_array_equal(j1[0], jac[k, :n])


def test_declared_sparsity_is_the_support_of_an_independent_derivative(rows):
    """The pattern IPOPT is given (`sparsity`, read off the analytic Jacobian) against
    central differences of the scalar `values_one` at other random points: every entry
    that moves is declared, and every declared entry moves."""
    h = 1e-6
    batch = rows.sparsities()           # all knots in one batch, as build_program asks
    for k in range(4):
        one = rows.knot(k)
        support = set()
        for z in random_knots(3, seed=11):
            for j in range(KNOT_SIZE):
                dz = np.zeros(KNOT_SIZE)
                dz[j] = h
                fd = (one.values_one(z + dz) - one.values_one(z - dz)) / (2 * h)
                support |= {(int(i), j) for i in np.flatnonzero(np.abs(fd) > 1e-6)}
        assert support == set(one.sparsity(0)) == set(batch[k]), f"knot {k}"


def test_knots_with_the_same_definition_share_a_pattern(rows):
    """sparsities() evaluates each distinct (pinned, c_B, n_B) once: with repeated knots every
    knot still gets its own knot's pattern."""
    order = [2, 0, 2, 1, 0, 3, 2]
    repeated = KnotRows(rows.body, rows.pinned[order], rows.c_B[order], rows.n_B[order])
    assert repeated.sparsities() == [rows.sparsity(k) for k in order]
    assert rows.sparsity(0) != rows.sparsity(1)                     # the knots differ: the test can fail


def test_static_object_rows_balance_gravity(scene, rows):
    """Fingers pushing straight up with total m g hold the object: the object rows vanish."""
    body = rows.body
    one = KnotRows(body, np.ones((1, 4), bool), np.zeros((1, 4, 2)), np.tile([0.0, -1.0], (1, 4, 1)))
    z = np.zeros(KNOT_SIZE)
    z[SLICES["q"]] = np.tile([0.3, 1.2], 4)
    z[SLICES["lambda_n"]] = body.mass * 9.81 / 4        # normal (0, -1): force +y on the box
    kin = one.kinematics(z[None])
    # Symmetric lever arms cancel only if the tips are symmetric; check the force rows.
    np.testing.assert_allclose(one.evaluate(z[None], False)[0][0, 0:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(kin.f_W.sum(1)[0], [0.0, body.mass * 9.81], atol=1e-12)


def test_default_sharpness_is_tight_where_fingertips_round_corners():
    """A tip centre 9 mm beside a face and 1 mm past the corner is 9.07 mm from the box;
    the default sharpness must not over-estimate that (with k = 200 it said 10 mm)."""
    from trajectotree.config import CitoConfig
    offsets = face_offsets(0.20, 0.10)
    p = np.array([[-0.10907, 0.05112]])
    exact = ConvexPolygon.box(0.20, 0.10).signed_distance(p[0])
    assert smooth_distance(p, offsets, CitoConfig().sdf_sharpness)[0][0] <= exact + 1e-4
    assert smooth_distance(p, offsets, 200.0)[0][0] > exact + 5e-4
