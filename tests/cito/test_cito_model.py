"""The CITO model against independent references: the plant's mass matrix, gravity
and kinematics, the exact box distance, and finite differences of the Jacobian."""

import math

import numpy as np
import pytest

from trajectotree.cito.contact import smooth_distance, smooth_normal
from trajectotree.cito.knot import BodyParams, KnotRows, _smooth_contact
from trajectotree.cito.variables import knot_block
from trajectotree.config import CitoConfig, ObjectConfig, SceneConfig
from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.plant import NUM_FINGERS, build_scene

# Polygon objects: an equilateral triangle of side 0.14 m, a regular hexagon of
# circumradius 0.07 m (the polygon gallery's shapes), and an irregular quadrilateral.
TRIANGLE_POINTS = tuple(
    (0.14 / np.sqrt(3) * np.cos(a), 0.14 / np.sqrt(3) * np.sin(a)) for a in np.pi / 2 + 2 * np.pi / 3 * np.arange(3)
)
HEXAGON_POINTS = tuple((0.07 * np.cos(a), 0.07 * np.sin(a)) for a in np.pi / 3 * np.arange(6))
QUAD_POINTS = ((-0.09, -0.05), (0.08, -0.06), (0.06, 0.06), (-0.05, 0.04))
TRIANGLE = ConvexPolygon.from_points(TRIANGLE_POINTS)


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
            M[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = block
        np.testing.assert_allclose(M, M_plant, atol=1e-12)
        np.testing.assert_allclose(
            hand.gravity_forces(q).ravel(), plant.CalcGravityGeneralizedForces(ctx)[iv], atol=1e-12
        )
        np.testing.assert_allclose(hand.fingertips(q), scene.fingertip_positions(q), atol=1e-9)
        J_plant = scene.fingertip_jacobians(q)
        J = hand.jacobians(q)
        for i in range(NUM_FINGERS):
            np.testing.assert_allclose(J[i], J_plant[i][:, 2 * i : 2 * i + 2], atol=1e-9)


def test_hand_ik_inverts_the_kinematics(hand):
    q = np.array([0.3, 1.2, -0.2, 0.9, 0.1, 1.5, -0.4, 0.7])
    tips = hand.fingertips(q)
    for i in range(NUM_FINGERS):
        np.testing.assert_allclose(hand.ik(i, tips[i]), q[2 * i : 2 * i + 2], atol=1e-9)
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
    faces = box.normals, box.offsets
    rng = np.random.default_rng(1)
    s = rng.uniform(0, box.perimeter, 400)
    s = s[[box.corner_distance(si) > 0.015 for si in s]]  # the search's corner margin
    for lift in (0.0, 0.01, 0.03):  # on the surface, tip centres, further out
        pts = np.array([box.point(si)[0] + lift * box.point(si)[1] for si in s])
        normals = np.array([box.point(si)[1] for si in s])
        phi, grad, hess = smooth_distance(pts, *faces, 200.0)
        exact = np.array([box.signed_distance(p) for p in pts])
        assert np.all(phi >= exact - 1e-12)  # log-sum-exp over-estimates the max
        # Bound: log(1 + exp(-k * 0.015)) / k = 0.24 mm on the surface 15 mm from a corner.
        np.testing.assert_allclose(phi, exact, atol=2.5e-4)
        n, _ = smooth_normal(grad, hess)
        np.testing.assert_allclose(n, normals, atol=0.05)
    # At face centres the error is below a micrometre, and at a corner at most log(4)/k.
    centres = np.array([[0.1, 0.0], [0.0, 0.05], [-0.1, 0.0], [0.0, -0.05]])
    np.testing.assert_allclose(smooth_distance(centres, *faces, 200.0)[0], 0.0, atol=1e-6)
    assert 0.0 < smooth_distance(np.array([[0.1, 0.05]]), *faces, 200.0)[0][0] <= np.log(4) / 200.0 + 1e-12
    np.testing.assert_array_equal(box.normals, [[1, 0], [0, 1], [-1, 0], [0, -1]])  # right, top, left, bottom
    np.testing.assert_array_equal(box.offsets, [0.1, 0.05, 0.1, 0.05])


def _min_corner_sine(shape: ConvexPolygon) -> float:
    """The smallest sin(interior angle) over the corners: a point on a face delta from a corner
    is at least delta times this below the neighbouring face's plane."""
    d = shape.directions
    return float(np.min(np.abs(d[:, 0] * np.roll(d, 1, axis=0)[:, 1] - d[:, 1] * np.roll(d, 1, axis=0)[:, 0])))


@pytest.mark.parametrize("points", [TRIANGLE_POINTS, HEXAGON_POINTS, QUAD_POINTS], ids=["triangle", "hexagon", "quad"])
def test_smooth_distance_of_a_polygon_matches_the_exact_distance(points):
    """Away from the corners (15 mm, the search's margin) on the surface, at tip centres and
    further out, the smooth distance is the exact one to within the log-sum-exp bound of the
    neighbouring faces, with the face's normal; near the corners, inside or on the polygon,
    it is never below the exact distance and at most log(V)/k above it."""
    shape = ConvexPolygon.from_points(points)
    V, k = len(shape.vertices), CitoConfig().sdf_sharpness
    rng = np.random.default_rng(5)
    s = rng.uniform(0, shape.perimeter, 600)
    s = s[[shape.corner_distance(si) > 0.015 for si in s]]
    p, n = shape.points(s)
    for sharpness in (k, 200.0):
        # The other faces' softmax weights sum to at most rest; the distance is off by log(1 + rest)/k
        # and the normal by at most 2 rest (unit normals at most 2 apart).
        rest = (V - 1) * np.exp(-sharpness * 0.015 * _min_corner_sine(shape))
        tol = np.log(1 + rest) / sharpness
        for lift in (0.0, 0.01, 0.03):
            pts = p + lift * n
            phi, grad, hess = smooth_distance(pts, shape.normals, shape.offsets, sharpness)
            exact = shape.signed_distances(pts)
            np.testing.assert_allclose(exact, lift, atol=1e-12)  # the reference itself
            assert np.all(phi >= exact - 1e-12) and np.all(phi <= exact + tol + 1e-12)
            np.testing.assert_allclose(smooth_normal(grad, hess)[0], n, atol=2 * rest)
    assert tol > 1e-5  # the bound is not vacuous at k = 200
    # Near the corners: points inside or on the polygon (the exact distance is the max face distance).
    f = rng.integers(0, V, 400)
    u = rng.uniform(0, 0.015, (400, 2)) * (rng.uniform(size=(400, 1)) > 0.2)  # some on the faces
    near = shape.vertices[f] + u[:, :1] * shape.directions[f] - u[:, 1:] * np.roll(shape.directions, 1, axis=0)[f]
    phi = smooth_distance(near, shape.normals, shape.offsets, k)[0]
    exact = shape.signed_distances(near)
    assert np.all(exact <= 1e-15)
    assert np.all(phi >= exact - 1e-12) and np.all(phi <= exact + np.log(V) / k + 1e-12)
    assert np.max(phi - exact) > np.log(2) / k * 0.9  # at a corner: log(2)/k, the bound is tight there


def test_scalar_contact_equals_the_batch_for_polygons_and_the_closed_form_for_the_box():
    """values_one's _smooth_contact: the batch's numbers to rounding for a polygon, and for the box
    bit for bit the four-face closed form the box's plans were made with."""
    rng = np.random.default_rng(6)
    box = ConvexPolygon.box(0.20, 0.10)
    for shape in (box, TRIANGLE, ConvexPolygon.from_points(HEXAGON_POINTS)):
        faces = tuple((float(n[0]), float(n[1]), float(h)) for n, h in zip(shape.normals, shape.offsets))
        pts = rng.uniform(-0.15, 0.15, (50, 2))
        phi, grad, hess = smooth_distance(pts, shape.normals, shape.offsets, 1000.0)
        n = smooth_normal(grad, hess)[0]
        for p, ph, nn in zip(pts, phi, n):
            got = _smooth_contact(float(p[0]), float(p[1]), 1000.0, faces, 0.01)
            np.testing.assert_allclose(got, [ph - 0.01, *nn], atol=1e-12)
            if shape is box:
                bx, by, wa, wb = float(p[0]), float(p[1]), 0.1, 0.05
                d = (bx - wa, by - wb, -bx - wa, -by - wb)
                e = [math.exp(1000.0 * (dj - max(d))) for dj in d]
                total = e[0] + e[1] + e[2] + e[3]
                gx, gy = (e[0] - e[2]) / total, (e[1] - e[3]) / total
                norm = math.hypot(gx, gy)
                closed = (max(d) + math.log(total) / 1000.0 - 0.01, gx / norm, gy / norm)
                assert got == closed


@pytest.mark.parametrize("shape", [ConvexPolygon.box(0.20, 0.10), TRIANGLE])
def test_smooth_normal_jacobian_matches_finite_differences(shape):
    offsets = shape.normals, shape.offsets
    p = np.array([[0.105, 0.03], [0.09, 0.06], [-0.02, -0.07]])
    _, grad, hess = smooth_distance(p, *offsets, 200.0)
    n, dn = smooth_normal(grad, hess)
    h = 1e-7
    for j in range(2):
        dp = np.zeros(2)
        dp[j] = h
        n_plus = smooth_normal(*smooth_distance(p + dp, *offsets, 200.0)[1:])[0]
        n_minus = smooth_normal(*smooth_distance(p - dp, *offsets, 200.0)[1:])[0]
        np.testing.assert_allclose(dn[:, :, j], (n_plus - n_minus) / (2 * h), atol=1e-5)


@pytest.fixture(scope="module")
def triangle_scene():
    return build_scene(SceneConfig(object=ObjectConfig(vertices=TRIANGLE_POINTS)))


@pytest.fixture(scope="module")
def other_hand_scenes():
    """Drake's three-finger gripper with its brick, and the five-finger hand with the box."""
    brick = SceneConfig(hand="drake_planar_gripper", box_width=0.1, box_height=0.1, box_mass=0.028)
    return {"gripper": build_scene(brick), "five": build_scene(SceneConfig(hand="planar_hand5"))}


@pytest.fixture(scope="module", params=["box", "triangle", "gripper", "five"])
def rows(request, scene):
    """Knots of the box's scene and of the triangle's (3 faces: its own smooth distance and inertia),
    and of the three- and five-finger hands (their knot layouts: 9 + 11 F columns)."""
    if request.param == "triangle":
        scene = request.getfixturevalue("triangle_scene")
    elif request.param in ("gripper", "five"):
        scene = request.getfixturevalue("other_hand_scenes")[request.param]
    F = scene.num_fingers
    rng = np.random.default_rng(2)
    fingers = [i % 4 for i in range(F)]  # the four-finger pattern, cut or repeated
    pinned = np.array([[1, 1, 1, 1], [0, 0, 0, 0], [1, 0, 1, 0], [0, 1, 1, 1]], bool)[:, fingers]
    normals = np.tile(np.array([[0.0, -1.0], [0.0, 1.0], [0.0, 1.0], [0.0, -1.0]])[fingers], (4, 1, 1))
    return KnotRows(BodyParams(scene, 200.0, mu=scene.config.mu), pinned, rng.uniform(-0.1, 0.1, (4, F, 2)), normals)


def test_body_params_take_the_object_shape(rows):
    body = rows.body
    assert len(body.normals) == len(body.offsets) == len(body.shape.vertices)
    np.testing.assert_array_equal(body.normals, body.shape.normals)
    assert body.inertia == body.shape.inertia(body.mass)
    if body.shape.is_box:  # bit for bit the box's closed form
        w, h = (2 * a for a in body.shape.box_half)
        assert body.inertia == body.mass * (w**2 + h**2) / 12.0
    else:  # an equilateral triangle plate: m a^2 / 12
        assert body.inertia == pytest.approx(body.mass * 0.14**2 / 12, rel=1e-12)


def random_knots(rows, n, seed=3):
    block = rows.layout.block
    rng = np.random.default_rng(seed)
    Z = rng.uniform(-1, 1, (n, block.size))
    Z[:, block.slices["x"]][:, :2] *= 0.05  # object positions within 5 cm
    return Z


def test_knot_jacobian_matches_finite_differences(rows):
    Z = random_knots(rows, 4)
    val, jac = rows.evaluate(Z, True)
    h = 1e-6
    assert Z.shape[1] == 9 + 11 * rows.layout.num_fingers
    for k in range(4):
        fd = np.zeros((val.shape[1], Z.shape[1]))
        for j in range(Z.shape[1]):
            dZ = np.zeros_like(Z)
            dZ[k, j] = h
            fd[:, j] = (rows.evaluate(Z + dZ, False)[0][k] - rows.evaluate(Z - dZ, False)[0][k]) / (2 * h)
        scale = np.maximum(1.0, np.abs(fd))
        assert np.max(np.abs(jac[k] - fd) / scale) < 1e-6, f"knot {k}"


def test_one_knot_paths_agree_with_the_batch(rows):
    Z = random_knots(rows, 4, seed=4)
    val, jac = rows.evaluate(Z, True)
    for k in range(4):
        one = rows.knot(k)
        n = one.num_rows[0]
        np.testing.assert_allclose(one.values_one(Z[k]), val[k, :n], atol=1e-12)
        v1, j1 = one.evaluate(Z[k : k + 1], True)
        np.testing.assert_array_equal(j1[0], jac[k, :n])


def test_declared_sparsity_is_the_support_of_an_independent_derivative(rows):
    """The pattern IPOPT is given (`sparsity`, read off the analytic Jacobian) against
    central differences of the scalar `values_one` at other random points: every entry
    that moves is declared, and every declared entry moves."""
    h = 1e-6
    batch = rows.sparsities()  # all knots in one batch, as build_program asks
    for k in range(4):
        one = rows.knot(k)
        support = set()
        for z in random_knots(rows, 3, seed=11):
            for j in range(len(z)):
                dz = np.zeros(len(z))
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
    assert rows.sparsity(0) != rows.sparsity(1)  # the knots differ: the test can fail


def test_static_object_rows_balance_gravity(scene, rows):
    """Fingers pushing straight up with total m g hold the object: the object rows vanish."""
    body, F = rows.body, rows.layout.num_fingers
    one = KnotRows(body, np.ones((1, F), bool), np.zeros((1, F, 2)), np.tile([0.0, -1.0], (1, F, 1)))
    block = knot_block(F)
    z = np.zeros(block.size)
    z[block.slices["q"]] = np.tile([0.3, 1.2], F)
    z[block.slices["lambda_n"]] = body.mass * 9.81 / F  # normal (0, -1): force +y on the box
    kin = one.kinematics(z[None])
    # Symmetric lever arms cancel only if the tips are symmetric; check the force rows.
    np.testing.assert_allclose(one.evaluate(z[None], False)[0][0, 0:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(kin.f_W.sum(1)[0], [0.0, body.mass * 9.81], atol=1e-12)


def test_default_sharpness_is_tight_where_fingertips_round_corners():
    """A tip centre 9 mm beside a face and 1 mm past the corner is 9.07 mm from the box;
    the default sharpness must not over-estimate that (with k = 200 it said 10 mm)."""
    box = ConvexPolygon.box(0.20, 0.10)
    p = np.array([[-0.10907, 0.05112]])
    exact = box.signed_distance(p[0])
    assert smooth_distance(p, box.normals, box.offsets, CitoConfig().sdf_sharpness)[0][0] <= exact + 1e-4
    assert smooth_distance(p, box.normals, box.offsets, 200.0)[0][0] > exact + 5e-4
