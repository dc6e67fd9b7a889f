"""Grasp matrix and the frictional form-closure LP against analytic cases."""

import numpy as np
import pytest

from trajectotree.geometry import ConvexPolygon
from trajectotree.search.grasp import (
    MU_CAP,
    ClosurePolynomials,
    FormClosure,
    FormClosureLp,
    closure_edges_parts,
    grasp_matrix,
    in_closure_many,
)

BOX = ConvexPolygon.box(0.20, 0.10)  # corners at arclength 0, 0.1, 0.3, 0.4; perimeter 0.6
RIGHT_MID, LEFT_MID = 0.05, 0.35  # (0.1, 0) and (-0.1, 0): an antipodal pair
TOP_X05, BOTTOM_XM05 = 0.15, 0.45  # (0.05, 0.05) and (-0.05, -0.05): a pair along a 45 degree line


def test_grasp_matrix_columns_are_the_contact_wrenches():
    # Right face, mid-height: pushing (lambda_n) gives f = -n = (-1, 0) through the centre,
    # the tangential force f = t = (0, 1) at lever arm 0.1 gives torque +0.1.
    G = grasp_matrix([[0.1, 0.0]], [[1.0, 0.0]])
    np.testing.assert_allclose(G, [[-1.0, 0.0], [0.0, 1.0], [0.0, 0.1]])
    # Top face at x = 0.05: push (0, -1) at (0.05, 0.05) -> torque 0.05 * -1 = -0.05;
    # tangent t = z x n = (-1, 0) -> torque -(0.05 * -1) = 0.05.
    G = grasp_matrix([[0.05, 0.05]], [[0.0, 1.0]])
    np.testing.assert_allclose(G, [[0.0, -1.0], [-1.0, 0.0], [-0.05, 0.05]])


def test_grasp_matrix_matches_cross_products():
    rng = np.random.default_rng(0)
    s = rng.uniform(0, BOX.perimeter, 4)
    p, n = zip(*(BOX.point(v) for v in s))
    G = grasp_matrix(np.array(p), np.array(n))
    lam = rng.uniform(0.1, 1.0, 8)
    f = [-lam[2 * i] * n[i] + lam[2 * i + 1] * np.array([-n[i][1], n[i][0]]) for i in range(4)]
    wrench = np.r_[np.sum(f, axis=0), sum(p[i][0] * f[i][1] - p[i][1] * f[i][0] for i in range(4))]
    np.testing.assert_allclose(G @ lam, wrench, atol=1e-12)


def test_opposed_pairs_are_in_form_closure_with_the_analytic_margin():
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    result = closure.check([RIGHT_MID, LEFT_MID])
    # Antipodal through the centre: lambda = (1, 0) per contact is optimal, d* = min(mu, 1) * 1.
    assert result.in_closure and result.rank == 3
    assert result.margin == pytest.approx(0.7, abs=1e-6)
    np.testing.assert_allclose(result.forces, [[1.0, 0.0], [1.0, 0.0]], atol=1e-6)
    assert FormClosure(BOX, mu=1.5, min_margin=1e-3).check([RIGHT_MID, LEFT_MID]).margin == pytest.approx(1.0, abs=1e-6)
    # Two fingers below and two above, on opposite long faces.
    assert closure.check([0.55, 0.15, 0.25, 0.45]).in_closure


def test_contacts_on_one_face_are_not_in_form_closure():
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    result = closure.check([0.42, 0.47, 0.52, 0.57])  # all on the bottom face: nothing pushes down
    assert not result.in_closure
    assert result.margin <= 1e-9


def test_closure_is_lost_when_friction_drops():
    # Nguyen: two contacts are in force closure iff the line between them lies inside both
    # friction cones. Here the line is 45 degrees off the normals: closure iff mu > 1.
    contacts = [TOP_X05, BOTTOM_XM05]
    assert FormClosure(BOX, mu=1.2, min_margin=1e-3).check(contacts).in_closure
    assert not FormClosure(BOX, mu=0.8, min_margin=1e-3).check(contacts).in_closure


def test_rank_deficient_grasp_is_rejected():
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    result = closure.check([RIGHT_MID])  # one contact: rank 2 at most
    assert result.rank < 3 and not result.in_closure


def test_free_fingers_and_the_cache():
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    grasp = [0.55, 0.15, 0.25, 0.45]
    assert all(closure.is_free(grasp, i) for i in range(4))  # any three hold the box
    # A right/left pair plus one bottom contact: the bottom one may go, the side ones may not.
    grasp = [RIGHT_MID, LEFT_MID, 0.5]
    assert closure.is_free(grasp, 2) and not closure.is_free(grasp, 0) and not closure.is_free(grasp, 1)
    calls = closure.lp_calls
    closure.check(grasp)
    closure.check([s + BOX.perimeter for s in grasp])  # same contacts, arclength wrapped
    assert closure.lp_calls == calls + 1


def test_lp_is_built_once_and_updated():
    lp = FormClosureLp(2, mu=0.7)
    prog, shape = lp.prog, (lp.prog.num_vars(), len(lp.prog.GetAllConstraints()), len(lp.prog.GetAllCosts()))
    p, n = zip(*(BOX.point(s) for s in (RIGHT_MID, LEFT_MID)))
    good = grasp_matrix(np.array(p), np.array(n))
    p, n = zip(*(BOX.point(s) for s in (TOP_X05, BOTTOM_XM05)))
    bad = grasp_matrix(np.array(p), np.array(n))
    margins = []
    for G in (good, bad, good):
        margins.append(lp.solve(G)[0])
        # the same program, nothing added: only the equilibrium rows now hold this G
        assert lp.prog is prog
        assert (prog.num_vars(), len(prog.GetAllConstraints()), len(prog.GetAllCosts())) == shape
        np.testing.assert_array_equal(lp.equilibrium.evaluator().GetDenseA(), G)
    assert margins[0] == pytest.approx(0.7, abs=1e-6) and margins[1] <= 1e-9 and margins[2] == pytest.approx(margins[0])
    # FormClosure builds one LP per number of contacts, on first use, and reuses it afterwards
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    closure.check([RIGHT_MID, LEFT_MID, 0.5])
    built = dict(closure.lps)
    for grasp in ([0.05, 0.36, 0.52], [0.14, 0.49, 0.2], [0.55, 0.15, 0.25, 0.45], [0.56, 0.16, 0.26, 0.46]):
        closure.check(grasp)
    assert closure.lp_calls == 5 and sorted(closure.lps) == [3, 4] and closure.lps[3] is built[3]


def test_required_mu_of_two_contacts_is_the_angle_of_their_line():
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    # Nguyen: two contacts hold iff the line between them lies inside both cones. Top (0.05, 0.05)
    # and bottom (-0.05, -0.05): the line is 45 degrees off both normals, mu* = tan 45 = 1.
    assert closure.required_mu([TOP_X05, BOTTOM_XM05]) == pytest.approx(1.0, abs=1e-6)
    # top x = 0.06, bottom x = -0.01: mu* = |dx| / height = 0.07 / 0.1
    assert closure.required_mu([0.14, 0.49]) == pytest.approx(0.7, abs=1e-6)
    # right y = 0.03, left y = -0.01 (arclength 0.36): mu* = |dy| / width = 0.04 / 0.2
    assert closure.required_mu([0.08, 0.36]) == pytest.approx(0.2, abs=1e-6)
    # antipodal through the centre: any friction will do (an infimum, 0)
    assert closure.required_mu([RIGHT_MID, LEFT_MID]) == pytest.approx(0.0, abs=1e-6)
    # all on one face, or a single contact: never, whatever the friction
    assert closure.required_mu([0.42, 0.47, 0.52, 0.57]) == np.inf
    assert closure.required_mu([RIGHT_MID]) == np.inf


def test_required_mu_of_three_contacts_against_its_closed_form():
    # Top contact at x1, bottom contacts at x2 < x3. All normals are vertical, so the
    # horizontal forces are friction only: with N_t = N_2 + N_3, torque balance about the
    # centre gives 2 b f_t = -x1 N_t + x2 N_2 + x3 N_3 and |f_t| <= mu N_t. If x1 lies
    # between x2 and x3 no friction is needed (mu* = 0); if x1 > x3, the least friction is
    # with the bottom load on x3: mu* = (x1 - x3) / (2 b).
    closure = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    b = 0.05

    def top(x):
        return 0.1 + (0.1 - x)

    def bottom(x):
        return 0.5 + x

    assert closure.required_mu([top(0.06), bottom(-0.06), bottom(0.02)]) == pytest.approx(
        (0.06 - 0.02) / (2 * b), abs=1e-6
    )
    assert closure.required_mu([top(0.08), bottom(-0.02), bottom(0.04)]) == pytest.approx(
        (0.08 - 0.04) / (2 * b), abs=1e-6
    )
    assert closure.required_mu([top(0.01), bottom(-0.06), bottom(0.02)]) == pytest.approx(0.0, abs=1e-6)


def test_required_mu_is_the_lps_threshold():
    # On random contact sets the LP (an independent test) agrees: in closure 1 % above
    # required_mu, not 1 % below it.
    rng = np.random.default_rng(1)
    exact = FormClosure(BOX, mu=0.7, min_margin=1e-3)
    checked = 0
    for _ in range(200):
        s = rng.uniform(0, BOX.perimeter, rng.integers(2, 5))
        mu = exact.required_mu(s)
        if np.isinf(mu):
            assert not FormClosure(BOX, mu=9.0, min_margin=1e-9).check(s).in_closure
        elif mu > 1e-3:
            assert FormClosure(BOX, mu=1.01 * mu, min_margin=1e-9).check(s).in_closure
            assert not FormClosure(BOX, mu=0.99 * mu, min_margin=1e-9).check(s).in_closure
            checked += 1
    assert checked > 50
    # the batch call gives the same numbers as one call per set
    sets = [[0.14, 0.44, 0.52], [0.14, 0.49], [0.12, 0.36, 0.48, 0.54]]
    assert FormClosure(BOX, mu=0.7, min_margin=1e-3).required_mus(sets) == [exact.required_mu(s) for s in sets]


def test_closure_polynomials_agree_with_the_edge_test():
    # required_mu bisects with the cubic side polynomials; they must decide exactly as
    # in_closure_many does, on grid contacts (corners and repeated contacts included) and random ones
    rng = np.random.default_rng(2)
    for k in (2, 3, 4):
        s = np.r_[rng.choice(np.round(np.arange(0, BOX.perimeter, 0.01), 9), 2000 * k), rng.uniform(0, 0.6, 500 * k)]
        p, n = BOX.points(s)
        A, B = closure_edges_parts(p.reshape(-1, k, 2), n.reshape(-1, k, 2))
        polynomials = ClosurePolynomials(A, B)
        for mu in (1e-5, 0.05, 0.2, 0.49, 0.7, 1.0, 3.0, MU_CAP):
            decided = polynomials.in_closure(mu)
            np.testing.assert_array_equal(decided, in_closure_many(A, B, mu))
            assert 0 < decided.sum() < len(decided) or mu in (1e-5, MU_CAP) or k == 2
    rows = np.array([3, 1, 4])
    np.testing.assert_array_equal(polynomials.subset(rows).in_closure(0.3), polynomials.in_closure(0.3)[rows])


def test_the_box_symmetries_share_a_stance_key_and_its_friction():
    # the table computes required_mu once per key: the half turn and the mirrors of a stance need the
    # same friction (to the bisection's resolution), and a polygon's stances are only sorted
    from trajectotree.search.grasp import required_mu_many
    from trajectotree.search.initial_grasp import symmetric_key

    rng = np.random.default_rng(4)
    grid = np.round(np.arange(0.0, BOX.perimeter, 0.01), 9)
    corner_free = grid[[BOX.corner_distance(s) >= 0.015 for s in grid]]  # a corner's normal is either face's
    stances = rng.choice(corner_free, size=(300, 3))
    images = [stances, stances + 0.3, 0.4 - stances, 0.7 - stances]  # P/2 = 0.3, 2 h + w = 0.4
    keys = [symmetric_key(BOX, np.mod(x, BOX.perimeter)) for x in images]
    for k in keys[1:]:
        np.testing.assert_array_equal(k, keys[0])
    mus = [required_mu_many(*(a.reshape(-1, 3, 2) for a in BOX.points(x.ravel()))) for x in images]
    for m in mus[1:]:
        np.testing.assert_allclose(m, mus[0], atol=2e-8)
    triangle = ConvexPolygon.from_points(((0.07, -0.04), (0.0, 0.08), (-0.07, -0.04)))
    np.testing.assert_array_equal(symmetric_key(triangle, stances[:, ::-1]), np.sort(stances, axis=1))
