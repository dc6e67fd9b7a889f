"""Grasp matrix and the frictional form-closure test (paper Sec. III-A, IsFeasible).

Contact force lambda_i = (lambda_n, lambda_t) of finger i lives in its local contact
frame (normal, tangent). The force the finger applies ON the object, in B, is
f_i = -lambda_n n_B + lambda_t t_B with the outward normal n_B and t_B = z x n_B
(trajectotree.geometry), so lambda_n >= 0 pushes. Its wrench about the object's origin is
(f_x, f_y, p_BC x f). The grasp matrix G (3 x 2k) maps lambda to the net wrench.

Frictional form closure is tested with the LP of the Springer Handbook of Robotics
(grasping chapter, "frictional form closure" test):

    maximize d  s.t.  G lambda = 0,
                      mu lambda_n -+ lambda_t >= d   (the two facets of each planar cone),
                      lambda_n >= d,
                      sum lambda_n <= k,
and the grasp is in frictional form closure iff rank G = 3 and d* > 0 (here d* must exceed
SearchConfig.min_closure_margin). The LP depends only on the contacts in the object frame,
never on the object pose, so results are cached by contact arclengths.

`required_mu` is the smallest friction coefficient at which contacts are in frictional form
closure, a number users can compare with the scene's mu. It uses an exact, vectorized test
instead of the LP: the 2k cone edges w = G_i (1, +-mu) positively span R^3 iff they span it
(rank 3) and no plane through the origin has them all on one side. If the cone is not R^3,
one of its facets is such a plane and contains two edges, so testing the planes through every
pair of edges is exact. Closure only grows with mu (the cones grow), so bisection on mu finds
the threshold; tests/test_grasp.py checks it against closed forms and against the LP.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.solvers import ClpSolver, MathematicalProgram, SolverOptions

from trajectotree.geometry import ConvexPolygon
from trajectotree.scene.statics import edge_wrenches_W

WRENCH_DIM = 3  # planar wrench (f_x, f_y, tau_z)
ARCLENGTH_KEY_DIGITS = 9  # arclengths equal to 1 nm share a cache entry
MU_CAP = 10.0  # required_mu above this is reported as inf (scene.mu is at most 5)
MU_BISECTIONS = 30  # bisection steps of required_mu: MU_CAP / 2^30 ~ 1e-8
SIDE_TOLERANCE = 1e-12  # relative; an edge this close to a plane counts as on it (not strictly on a side)


def grasp_matrix(p_BC, n_B) -> np.ndarray:
    """G (3, 2k): column pair i maps (lambda_n, lambda_t) of contact i to its wrench on the object."""
    p_BC, n_B = np.atleast_2d(p_BC).astype(float), np.atleast_2d(n_B).astype(float)
    t_B = np.stack([-n_B[:, 1], n_B[:, 0]], axis=1)
    G = np.zeros((WRENCH_DIM, 2 * len(p_BC)))
    for i, (p, n, t) in enumerate(zip(p_BC, n_B, t_B)):
        for j, direction in enumerate((-n, t)):
            G[:2, 2 * i + j] = direction
            G[2, 2 * i + j] = p[0] * direction[1] - p[1] * direction[0]
    return G


def closure_edges_parts(p_BC, n_B) -> tuple[np.ndarray, np.ndarray]:
    """(A, B), each (..., k, 3): contact i's cone edges are A_i +- mu B_i, the wrenches of a
    unit push (lambda_n = 1) and a unit tangential force. Works on stacks (..., k, 2)."""
    p, n = np.asarray(p_BC, dtype=float), np.asarray(n_B, dtype=float)
    t = np.stack([-n[..., 1], n[..., 0]], axis=-1)

    def wrench(f):
        return np.concatenate([f, (p[..., 0] * f[..., 1] - p[..., 1] * f[..., 0])[..., None]], axis=-1)

    return wrench(-n), wrench(t)


def spans_wrench_space(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(M,) rank G = 3: the edges span R^3 at every mu > 0."""
    return np.linalg.matrix_rank(np.concatenate([A, B], axis=1), tol=1e-9) == WRENCH_DIM


def in_closure_many(A: np.ndarray, B: np.ndarray, mu, spans: np.ndarray | None = None) -> np.ndarray:
    """Exact frictional form closure of stacks of k contacts (A, B from closure_edges_parts,
    shape (M, k, 3)) at friction mu > 0 (scalar or (M,)): (M,) bool, margin-free (d* > 0).
    `spans` (spans_wrench_space) may be passed to skip the rank test."""
    mu = np.broadcast_to(np.asarray(mu, dtype=float), A.shape[:1])[:, None, None]
    edges = np.concatenate([A + mu * B, A - mu * B], axis=1)  # (M, 2k, 3)
    edges /= np.sqrt(np.einsum("mec,mec->me", edges, edges))[..., None]  # unit edges: tolerances are relative
    j, l = np.triu_indices(edges.shape[1], 1)
    planes = np.cross(edges[:, j], edges[:, l])  # (M, P, 3) normals of the planes through edge pairs
    side = np.einsum("mpc,mec->mpe", planes, edges)
    size = np.sqrt(np.einsum("mpc,mpc->mp", planes, planes))
    split = (side.max(axis=2) > SIDE_TOLERANCE * size) & (side.min(axis=2) < -SIDE_TOLERANCE * size)
    degenerate = size <= SIDE_TOLERANCE  # two parallel edges: no plane
    spans = spans_wrench_space(A, B) if spans is None else spans
    return spans & np.all(split | degenerate, axis=1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (3), for stacks (np.cross's axis handling costs more than this)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


class ClosurePolynomials:
    """in_closure_many of one stack (M, k, 3) at many friction coefficients, for bisection.

    Edge e is A_e + s_e mu B_e (s_e = +-1), so the normal of the plane through edges a and b is
    quadratic in mu and each other edge's side of it, det(e_a, e_b, e_c), cubic: their
    coefficients are computed once and each mu costs one polynomial evaluation instead of the
    edges' cross products. The test is in_closure_many's, with its tolerances relative to the
    edges' lengths (side / |e_c| against SIDE_TOLERANCE |e_a x e_b|, the pair degenerate when
    |e_a x e_b| <= SIDE_TOLERANCE |e_a| |e_b|), and a pair's own two edges left out (their
    sides are zero)."""

    def __init__(self, A: np.ndarray, B: np.ndarray, spans: np.ndarray | None = None):
        k = A.shape[1]
        EA, EB = np.concatenate([A, A], axis=1), np.concatenate([B, -B], axis=1)  # e = EA + mu EB, (M, 2k, 3)
        j, l = np.triu_indices(2 * k, 1)
        # each pair's other edges, (P, 2k - 2)
        others = np.array([[e for e in range(2 * k) if e not in (a, b)] for a, b in zip(j, l)], dtype=int)
        others = others.reshape(len(j), 2 * k - 2)
        C0, C1, C2 = (  # plane normals e_a x e_b = C0 + mu C1 + mu^2 C2, (M, P, 3)
            _cross(EA[:, j], EA[:, l]),
            _cross(EA[:, j], EB[:, l]) + _cross(EB[:, j], EA[:, l]),
            _cross(EB[:, j], EB[:, l]),
        )
        OA, OB = EA[:, others], EB[:, others]  # (M, P, 2k - 2, 3)

        def side(c, e):
            return np.einsum("mpc,mpec->mpe", c, e)

        self.D = (side(C0, OA), side(C1, OA) + side(C0, OB), side(C2, OA) + side(C1, OB), side(C2, OB))
        self.C = (C0, C1, C2)
        self.E = (  # |e|^2 = E0 + mu E1 + mu^2 E2, (M, 2k)
            np.einsum("mec,mec->me", EA, EA),
            2 * np.einsum("mec,mec->me", EA, EB),
            np.einsum("mec,mec->me", EB, EB),
        )
        self.pairs, self.others = (j, l), others
        self.spans = spans_wrench_space(A, B) if spans is None else spans

    def subset(self, rows: np.ndarray) -> ClosurePolynomials:
        """The polynomials of the stacks `rows` only."""
        out = object.__new__(ClosurePolynomials)
        out.D, out.C, out.E = (tuple(c[rows] for c in group) for group in (self.D, self.C, self.E))
        out.pairs, out.others, out.spans = self.pairs, self.others, self.spans[rows]
        return out

    def in_closure(self, mu) -> np.ndarray:
        """(M,) bool: in_closure_many at friction mu > 0 (scalar or (M,))."""
        mu = np.broadcast_to(np.asarray(mu, dtype=float), self.spans.shape)
        m2, m3 = mu[:, None], mu[:, None, None]
        D0, D1, D2, D3 = self.D
        C0, C1, C2 = self.C
        length = np.sqrt(self.E[0] + m2 * (self.E[1] + m2 * self.E[2]))  # (M, 2k)
        plane = C0 + m3 * (C1 + m3 * C2)  # e_a x e_b (its squared norm as a polynomial loses digits)
        size = np.sqrt(np.einsum("mpc,mpc->mp", plane, plane))  # (M, P)
        side = ((D3 * m3 + D2) * m3 + D1) * m3 + D0  # (M, P, 2k - 2): det(e_a, e_b, e_c)
        bound = SIDE_TOLERANCE * size[..., None] * length[:, self.others]
        split = np.any(side > bound, axis=2) & np.any(side < -bound, axis=2)
        j, l = self.pairs
        degenerate = size <= SIDE_TOLERANCE * length[:, j] * length[:, l]  # two parallel edges: no plane
        return self.spans & np.all(split | degenerate, axis=1)


def required_mu_many(p_BC, n_B, bisections: int = MU_BISECTIONS) -> np.ndarray:
    """(M,) the smallest friction coefficient at which each stack of contacts (M, k, 2) is in
    frictional form closure (an infimum: ~0 for, e.g., an antipodal pair), inf if not even at
    MU_CAP. Accurate to MU_CAP / 2^bisections."""
    A, B = closure_edges_parts(p_BC, n_B)
    polynomials = ClosurePolynomials(A, B)
    out = np.where(polynomials.in_closure(MU_CAP), np.nan, np.inf)
    # in closure at the resolution itself: every bisection step would pass, ending at the infimum 0
    # (closure only grows with mu), so these take no more steps
    out[polynomials.in_closure(MU_CAP / 2**bisections) & np.isnan(out)] = 0.0
    todo = np.flatnonzero(np.isnan(out))
    polynomials = polynomials.subset(todo)
    lo, hi = np.zeros(len(todo)), np.full(len(todo), MU_CAP)
    for _ in range(bisections):
        mid = 0.5 * (lo + hi)
        ok = polynomials.in_closure(mid)
        hi, lo = np.where(ok, mid, hi), np.where(ok, lo, mid)
    out[todo] = np.where(hi <= MU_CAP / 2**bisections, 0.0, hi)  # the last bracket holds 0: an infimum of 0
    return out


@dataclass(frozen=True)
class ClosureResult:
    in_closure: bool  # rank G = 3 and margin > min_margin
    margin: float  # N, the LP optimum d* (-inf when the LP failed)
    rank: int  # rank of the grasp matrix
    forces: np.ndarray  # (k, 2) the LP's (lambda_n, lambda_t) per contact


class FormClosureLp:
    """The LP for k contacts, built once; `solve` only updates G (UpdateCoefficients).

    `prog` is its one MathematicalProgram and `equilibrium` the binding whose A is G."""

    def __init__(self, num_contacts: int, mu: float):
        self.num_contacts = k = num_contacts
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(2 * k + 1, "x")  # (lambda_n0, lambda_t0, ..., d)
        lam, d = x[: 2 * k], x[2 * k]
        # Column-major matrices: pydrake binds them to its dense overload at once; a row-major one
        # first tries the sparse overload, whose caster imports scipy.sparse (0.2-0.9 s in a fresh process).
        self.equilibrium = prog.AddLinearEqualityConstraint(
            np.zeros((WRENCH_DIM, 2 * k), order="F"), np.zeros(WRENCH_DIM), lam
        )
        # One constraint block (cone facets, lambda_n >= d, normalization): Clp sets up faster.
        A = np.zeros((3 * k + 1, 2 * k + 1))
        for i in range(k):
            A[3 * i, [2 * i, 2 * i + 1, 2 * k]] = (mu, -1.0, -1.0)
            A[3 * i + 1, [2 * i, 2 * i + 1, 2 * k]] = (mu, 1.0, -1.0)
            A[3 * i + 2, [2 * i, 2 * k]] = (1.0, -1.0)
        A[3 * k, 0 : 2 * k : 2] = 1.0
        prog.AddLinearConstraint(
            np.asfortranarray(A), np.r_[np.zeros(3 * k), -np.inf], np.r_[np.full(3 * k, np.inf), k], x
        )
        prog.AddLinearCost(-d)
        self.prog, self._lam, self._d = prog, lam, d
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, G: np.ndarray) -> tuple[float, np.ndarray]:
        """(d*, lambda (k, 2)) for the grasp matrix G; d* = -inf if Clp reports failure."""
        self.equilibrium.evaluator().UpdateCoefficients(G, np.zeros(WRENCH_DIM))
        result = self._solver.Solve(self.prog, None, self._options)
        if not result.is_success():
            return -np.inf, np.zeros((self.num_contacts, 2))
        return float(result.GetSolution(self._d)), result.GetSolution(self._lam).reshape(-1, 2)


class FormClosure:
    """Frictional form closure of contacts given by arclength on one object outline, with a cache."""

    def __init__(self, boundary: ConvexPolygon, mu: float, min_margin: float):
        self.boundary, self.mu, self.min_margin = boundary, mu, min_margin
        self.lps: dict[int, FormClosureLp] = {}  # one LP per number of contacts, built on first use
        self._cache: dict[tuple[float, ...], ClosureResult] = {}
        self._required_mu: dict[tuple[float, ...], float] = {}
        self.lp_calls = 0  # LP solves so far (cache hits excluded)

    def key(self, arclengths) -> tuple[float, ...]:
        per = self.boundary.perimeter
        return tuple(round(float(s) % per, ARCLENGTH_KEY_DIGITS) for s in arclengths)

    def check(self, arclengths) -> ClosureResult:
        """Closure of the contacts at `arclengths` (forces come back in the same order)."""
        key = self.key(arclengths)
        if key not in self._cache:
            self._cache[key] = self._solve(key)
        return self._cache[key]

    def required_mu(self, arclengths) -> float:
        """The smallest friction coefficient at which these contacts are in frictional form
        closure (exact test, bisection to ~1e-8; see the module doc); memoized."""
        return self.required_mus([arclengths])[0]

    def required_mus(self, contact_sets) -> list[float]:
        """required_mu of several contact sets in one vectorized bisection (shorter sets are
        padded with a copy of their first contact, which changes neither cone nor rank)."""
        keys = [self.key(arclengths) for arclengths in contact_sets]
        todo = sorted({key for key in keys if key not in self._required_mu and key})
        if todo:
            k = max(map(len, todo))
            points = [[self.boundary.point(s) for s in key + (key[0],) * (k - len(key))] for key in todo]
            values = required_mu_many(
                np.array([[p for p, _ in row] for row in points]), np.array([[n for _, n in row] for row in points])
            )
            self._required_mu.update(zip(todo, values.tolist()))
        return [self._required_mu.get(key, np.inf) for key in keys]  # no contact at all: never

    def is_free(self, arclengths, finger: int) -> bool:
        """Finger `finger` may let go: the other contacts alone are in form closure."""
        others = [s for i, s in enumerate(arclengths) if i != finger]
        return self.check(others).in_closure

    def _solve(self, arclengths) -> ClosureResult:
        points = [self.boundary.point(s) for s in arclengths]
        p_BC = np.array([p for p, _ in points])
        n_B = np.array([n for _, n in points])
        G = grasp_matrix(p_BC, n_B)
        k = len(arclengths)
        if k not in self.lps:
            self.lps[k] = FormClosureLp(k, self.mu)
        self.lp_calls += 1
        margin, forces = self.lps[k].solve(G)
        rank = int(np.linalg.matrix_rank(G, tol=1e-9))
        return ClosureResult(
            in_closure=rank == WRENCH_DIM and margin > self.min_margin, margin=margin, rank=rank, forces=forces
        )


# -- in space ------------------------------------------------------------------------------------
SPATIAL_WRENCH_DIM = 6  # (f, tau) in W
# d* above this counts as closure: d* is at most 1 / (k m) (about 0.03 for 4 contacts of 8 edges), and a
# set on the boundary of closure solves to ~1e-10 (Clp's tolerances)
CLOSURE_MIN_MARGIN = 1e-6


class SpatialClosureLp:
    """Frictional force closure of k contacts in space, with linearized cones (statics.pyramid_edges):

        maximize d  s.t.  W x = 0,  sum x = 1,  x_e >= d  for every edge e,

    x the magnitudes along the k m pyramid edges, W (6, k m) their wrenches about the object's
    centre with the torque rows divided by a length (the object's half-size: forces and torques
    weigh alike). The contacts are in closure iff rank W = 6 and d* > 0 (here > min_margin): zero
    is then a strictly positive combination of wrenches that span R^6, so every wrench is one.
    Built once; `solve` only updates W (UpdateCoefficients)."""

    def __init__(self, num_contacts: int, num_edges: int):
        n = num_contacts * num_edges
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(n + 1, "x")  # edge magnitudes, then d
        self.equilibrium = prog.AddLinearEqualityConstraint(
            np.zeros((SPATIAL_WRENCH_DIM, n), order="F"), np.zeros(SPATIAL_WRENCH_DIM), x[:n]
        )
        prog.AddLinearEqualityConstraint(np.ones((1, n)), np.ones(1), x[:n])
        prog.AddLinearConstraint(  # x_e - d >= 0
            np.asfortranarray(np.hstack([np.eye(n), -np.ones((n, 1))])), np.zeros(n), np.full(n, np.inf), x
        )
        prog.AddLinearCost(-x[n])
        self.prog, self._x, self.num_edges = prog, x, num_edges
        self._solver, self._options = ClpSolver(), SolverOptions()
        self.lp_calls = 0

    def solve(self, W: np.ndarray) -> float:
        """d* for the scaled edge wrenches W (6, k m); -inf when Clp reports failure."""
        self.equilibrium.evaluator().UpdateCoefficients(np.asfortranarray(W), np.zeros(SPATIAL_WRENCH_DIM))
        self.lp_calls += 1
        result = self._solver.Solve(self.prog, None, self._options)
        return float(result.GetSolution(self._x[-1])) if result.is_success() else -np.inf


class SpatialClosure:
    """The closure test of contacts on one object at one friction, an LP per number of contacts."""

    def __init__(self, mu: float, half_size: float, num_edges: int = 8, min_margin: float = CLOSURE_MIN_MARGIN):
        self.mu, self.half_size, self.num_edges, self.min_margin = mu, half_size, num_edges, min_margin
        self.lps: dict[int, SpatialClosureLp] = {}

    def check(self, p_WC, n_W) -> ClosureResult:
        """Closure of contacts p_WC (k, 3) relative to the object's centre with outward normals n_W (k, 3)."""
        W = edge_wrenches_W(p_WC, n_W, self.mu, self.num_edges)
        W[3:] /= self.half_size
        k = len(np.atleast_2d(p_WC))
        if k not in self.lps:
            self.lps[k] = SpatialClosureLp(k, self.num_edges)
        margin = self.lps[k].solve(W)
        rank = int(np.linalg.matrix_rank(W, tol=1e-9))
        return ClosureResult(
            in_closure=rank == SPATIAL_WRENCH_DIM and margin > self.min_margin,
            margin=margin,
            rank=rank,
            forces=np.zeros((k, 3)),  # the LP's magnitudes are per edge, not per contact
        )
