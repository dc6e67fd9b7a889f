"""Grasp matrix and the frictional form-closure test (paper Sec. III-A, IsFeasible).

Contact force lambda_i = (lambda_n, lambda_t) of finger i lives in its local contact
frame (normal, tangent). The force the finger applies ON the object, in B, is
f_i = -lambda_n n_B + lambda_t t_B with the outward normal n_B and t_B = z x n_B
(trajectotree.geometry), so lambda_n >= 0 pushes. Its wrench about the box origin is
(f_x, f_y, p_BC x f). The grasp matrix G (3 x 2k) maps lambda to the net wrench.

Frictional form closure is tested with the LP of the Springer Handbook of Robotics
(grasping chapter, "frictional form closure" test):

    maximize d  s.t.  G lambda = 0,
                      mu lambda_n -+ lambda_t >= d   (the two facets of each planar cone),
                      lambda_n >= d,
                      sum lambda_n <= k,
and the grasp is in frictional form closure iff rank G = 3 and d* > 0 (here d* must exceed
SearchConfig.min_closure_margin). The LP depends only on the contacts in the box frame,
never on the object pose, so results are cached by contact arclengths.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.solvers import ClpSolver, MathematicalProgram, SolverOptions

from trajectotree.geometry import BoxBoundary

WRENCH_DIM = 3      # planar wrench (f_x, f_y, tau_z)
ARCLENGTH_KEY_DIGITS = 9  # arclengths equal to 1 nm share a cache entry


def grasp_matrix(p_BC, n_B) -> np.ndarray:
    """G (3, 2k): column pair i maps (lambda_n, lambda_t) of contact i to its wrench on the box."""
    p_BC, n_B = np.atleast_2d(p_BC).astype(float), np.atleast_2d(n_B).astype(float)
    t_B = np.stack([-n_B[:, 1], n_B[:, 0]], axis=1)
    G = np.zeros((WRENCH_DIM, 2 * len(p_BC)))
    for i, (p, n, t) in enumerate(zip(p_BC, n_B, t_B)):
        for j, direction in enumerate((-n, t)):
            G[:2, 2 * i + j] = direction
            G[2, 2 * i + j] = p[0] * direction[1] - p[1] * direction[0]
    return G


@dataclass(frozen=True)
class ClosureResult:
    in_closure: bool      # rank G = 3 and margin > min_margin
    margin: float         # N, the LP optimum d* (-inf when the LP failed)
    rank: int             # rank of the grasp matrix
    forces: np.ndarray    # (k, 2) the LP's (lambda_n, lambda_t) per contact


class FormClosureLp:
    """The LP for k contacts, built once; `solve` only updates G (UpdateCoefficients)."""

    def __init__(self, num_contacts: int, mu: float):
        self.num_contacts = k = num_contacts
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(2 * k + 1, "x")  # (lambda_n0, lambda_t0, ..., d)
        lam, d = x[:2 * k], x[2 * k]
        self._equilibrium = prog.AddLinearEqualityConstraint(np.zeros((WRENCH_DIM, 2 * k)), np.zeros(WRENCH_DIM), lam)
        # One constraint block (cone facets, lambda_n >= d, normalization): Clp sets up faster.
        A = np.zeros((3 * k + 1, 2 * k + 1))
        for i in range(k):
            A[3 * i, [2 * i, 2 * i + 1, 2 * k]] = (mu, -1.0, -1.0)
            A[3 * i + 1, [2 * i, 2 * i + 1, 2 * k]] = (mu, 1.0, -1.0)
            A[3 * i + 2, [2 * i, 2 * k]] = (1.0, -1.0)
        A[3 * k, 0:2 * k:2] = 1.0
        prog.AddLinearConstraint(A, np.r_[np.zeros(3 * k), -np.inf], np.r_[np.full(3 * k, np.inf), k], x)
        prog.AddLinearCost(-d)
        self._prog, self._lam, self._d = prog, lam, d
        self._solver, self._options = ClpSolver(), SolverOptions()

    def solve(self, G: np.ndarray) -> tuple[float, np.ndarray]:
        """(d*, lambda (k, 2)) for the grasp matrix G; d* = -inf if Clp reports failure."""
        self._equilibrium.evaluator().UpdateCoefficients(G, np.zeros(WRENCH_DIM))
        result = self._solver.Solve(self._prog, None, self._options)
        if not result.is_success():
            return -np.inf, np.zeros((self.num_contacts, 2))
        return float(result.GetSolution(self._d)), result.GetSolution(self._lam).reshape(-1, 2)


class FormClosure:
    """Frictional form closure of contacts given by arclength on one box, with a cache."""

    def __init__(self, boundary: BoxBoundary, mu: float, min_margin: float):
        self.boundary, self.mu, self.min_margin = boundary, mu, min_margin
        self._lps: dict[int, FormClosureLp] = {}
        self._cache: dict[tuple[float, ...], ClosureResult] = {}
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
        if k not in self._lps:
            self._lps[k] = FormClosureLp(k, self.mu)
        self.lp_calls += 1
        margin, forces = self._lps[k].solve(G)
        rank = int(np.linalg.matrix_rank(G, tol=1e-9))
        return ClosureResult(in_closure=rank == WRENCH_DIM and margin > self.min_margin,
                             margin=margin, rank=rank, forces=forces)
