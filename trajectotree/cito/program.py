"""The CITO program builder shared by all three methods (general CITO, eqs. 1-10;
the plan-constrained variant of transition.py only changes the `ProgramSpec`).

Knots k = 0..K-1, dt apart. Linear parts go through Drake's native sparse linear
constraints and bounds: trapezoidal collocation (x_{k+1} = x_k + dt/2 (xd_k + xd_{k+1}),
the same for xd/xdd, q/qd, qd/qdd), the friction cone mu_plan lambda_n >= |lambda_t|,
lambda_n >= 0, slack >= 0, joint and torque limits, fixed x_0 and q_0, rest knots.
The nonlinear rows of every knot (knot.KnotRows) form one Python constraint over all the
knots' variables, evaluated vectorized with its analytic, block-diagonal sparse Jacobian; the
link rows (links.LinkRows, unless `cito.link_rows` is off) another over the pose and joints of
every knot whose pose or joints are free (_BatchConstraint), and so do the finger-finger rows
(fingers.FingerRows) of the spec's `finger_pairs` over those knots' joints.

Speed: IPOPT crosses into Python once per evaluation of each of the two constraints. Per-knot
constraints (13 per segment) cost Drake and pybind more in AutoDiff marshalling per call than one
batch costs in its wider gradients: on 9 segments of goal 0.861 the solves took 1.56 s instead of
1.85 s in the same iterations (issue 35).
Costs are many small native quadratic costs: Drake differentiates every cost
binding with AutoDiff over its own variables, which is cubic in their number.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import MathematicalProgram

from trajectotree.cito.fingers import FingerRows
from trajectotree.cito.knot import BodyParams, KnotRows
from trajectotree.cito.links import LinkRows
from trajectotree.cito.variables import CitoVariables, knot_block
from trajectotree.config import CitoConfig


@dataclass(frozen=True)
class ProgramSpec:
    """What distinguishes one CITO program from another."""

    dt: float  # s, knot spacing
    pinned: np.ndarray  # (K, 4) bool, finger pinned to a planned contact at knot k
    c_B: np.ndarray  # (K, 4, 2) m, pinned fingertip-centre target in B
    n_B: np.ndarray  # (K, 4, 2) planned contact normal in B
    clearance: np.ndarray  # (K, 4) m, least fingertip-surface gap of free fingers
    x0: np.ndarray  # (3,) fixed initial object pose
    q0: np.ndarray  # (8,) fixed initial joint angles
    rest_knots: np.ndarray  # knots where object and joint velocities are zero
    goal_poses: tuple  # per knot, an (n_k, 3) array of incremental goals x*_n (eq. 11)
    segment_length: int = 0  # M_hat knots per segment (0: not segmented)
    # keyframes formulation: the last knot's pose and joints fixed too (None: free), and the knots
    # where the object and hand accelerations are zero (static at a search node; () : none)
    x_end: np.ndarray | None = None  # (3,) fixed final object pose
    q_end: np.ndarray | None = None  # (8,) fixed final joint angles
    static_knots: tuple = ()
    # the pairs of fingers (i, j) kept apart by finger rows at the free knots (fingers.near_pairs; () : none)
    finger_pairs: tuple = ()
    # joint angles (2F each) the finger rows admit besides the fixed end knots: the search's nodes, which a
    # joint program's pinned knots reach without fixing them (its rows held 1 mm where a node had less)
    finger_nodes: tuple = ()

    @property
    def num_knots(self) -> int:
        return self.pinned.shape[0]

    @property
    def last_knot_fixed(self) -> bool:
        """Both the last knot's pose and joints fixed (keyframes: it is a search node)."""
        return self.x_end is not None and self.q_end is not None


@dataclass
class CitoProgram:
    prog: MathematicalProgram
    variables: CitoVariables
    rows: KnotRows
    spec: ProgramSpec
    knot_binding: object  # the knot rows of every knot, one binding (_BatchConstraint)
    knot_row_offsets: np.ndarray  # (K + 1,) knot k's rows are the binding's offsets[k]:offsets[k + 1]
    link_binding: object | None = None  # links.py's rows of every free knot, one binding (None when off)
    finger_binding: object | None = None  # fingers.py's rows of every free knot, one binding (None: no pairs)
    build_time_s: float = 0.0


class _BatchConstraint:
    """Drake's evaluator for the rows of a batch of knots as one constraint over all their
    variables (knot after knot, `width` each): float input gives the values, AutoDiffXd input the
    values and the gradient, each from one vectorized evaluation of every knot (rows.evaluate:
    KnotRows or LinkRows), the analytic Jacobian scattered into the binding's sparsity pattern
    (knot k's `patterns[k]`, block-diagonal). Knot k's rows are the first num_rows[k] of its batch
    row. Drake's solvers pass identity input gradients, which skip the chain rule's product."""

    def __init__(self, rows, num_rows: np.ndarray, width: int, patterns: list[list[tuple[int, int]]]):
        self.rows, self.width = rows, width
        num_rows = np.asarray(num_rows, dtype=int)
        depth = int(num_rows.max())  # rows of a knot in the batch's arrays
        self.valid = np.flatnonzero(np.arange(depth)[None, :] < num_rows[:, None])  # into the (K, depth) values
        self.offsets = np.concatenate([[0], np.cumsum(num_rows)])  # knot k's first row in the binding
        entries = np.array([(k, r, c) for k, pattern in enumerate(patterns) for r, c in pattern], dtype=int)
        kk, rr, cc = entries.T
        self.pattern_rows, self.pattern_cols = self.offsets[kk] + rr, kk * width + cc
        self.source = (kk * depth + rr) * width + cc  # into the (K, depth, width) Jacobians
        self.shape = (int(self.offsets[-1]), len(num_rows) * width)

    def sparsity(self) -> list[tuple[int, int]]:
        return list(zip(self.pattern_rows.tolist(), self.pattern_cols.tolist()))

    def jacobian(self, Z: np.ndarray):
        """(values (rows,), Jacobian (rows, variables), dense) at the knots' values Z (K, width)."""
        val, jac = self.rows.evaluate(Z, True)
        J = np.zeros(self.shape)
        J[self.pattern_rows, self.pattern_cols] = jac.reshape(-1)[self.source]
        return val.reshape(-1)[self.valid], J

    def __call__(self, z):
        if z.dtype == object:
            val, J = self.jacobian(ExtractValue(z)[:, 0].reshape(-1, self.width))
            G = ExtractGradient(z)
            identity = G.shape == (J.shape[1],) * 2 and np.count_nonzero(G) == G.shape[0] and np.all(G.diagonal() == 1)
            return InitializeAutoDiff(val, J if identity else sp.csr_matrix(J) @ G)[:, 0]
        Z = np.asarray(z, dtype=float).reshape(-1, self.width)
        return self.rows.evaluate(Z, False)[0].reshape(-1)[self.valid]


def _collocation(prog, a: np.ndarray, b: np.ndarray, dt: float):
    """a_{k+1} - a_k - dt/2 (b_k + b_{k+1}) = 0 for all k, one sparse binding."""
    K, n = a.shape
    # Row k n + j: a[k+1, j] - a[k, j] + h b[k, j] + h b[k+1, j], h = -dt/2 (scipy's kron and
    # hstack built the same matrix ~5x slower).
    r = np.arange((K - 1) * n)
    h = -0.5 * dt
    A = sp.csc_matrix(
        (
            np.concatenate([np.full(r.size, -1.0), np.ones(r.size), np.full(2 * r.size, h)]),
            (np.tile(r, 4), np.concatenate([r, r + n, K * n + r, K * n + n + r])),
        ),
        shape=(r.size, 2 * K * n),
    )
    return prog.AddLinearEqualityConstraint(A, np.zeros(A.shape[0]), np.concatenate([a.ravel(), b.ravel()]))


def _bounds(v: CitoVariables, spec: ProgramSpec, body: BodyParams):
    """Per-group (lower, upper) arrays of the bounding boxes."""
    hand = body.hand
    inf = np.inf
    lo = {name: np.full(getattr(v, name).shape, -inf) for name in ("x", "xd", "q", "qd", "tau", "lambda_n", "slack")}
    hi = {name: np.full(getattr(v, name).shape, inf) for name in lo}
    lo["q"][:], hi["q"][:] = hand.q_lower, hand.q_upper
    lo["tau"][:], hi["tau"][:] = -hand.tau_max, hand.tau_max
    lo["lambda_n"][:] = 0.0
    # A finger held off the box (clearance > 0) cannot push it; without this bound the relaxed
    # complementarity (eq. 5) lets it push through the gap at the price of a slack.
    hi["lambda_n"][spec.clearance > 0] = 0.0
    lo["slack"][:] = 0.0
    lo["x"][0] = hi["x"][0] = spec.x0
    lo["q"][0] = hi["q"][0] = spec.q0
    rest = np.asarray(spec.rest_knots, dtype=int)
    for name in ("xd", "qd"):
        lo[name][rest] = hi[name][rest] = 0.0
    if spec.x_end is not None:
        lo["x"][-1] = hi["x"][-1] = spec.x_end
    if spec.q_end is not None:
        lo["q"][-1] = hi["q"][-1] = spec.q_end
    if len(spec.static_knots):  # only then bounds on the accelerations (the joint program has none)
        for name in ("xdd", "qdd"):
            lo[name] = np.full(getattr(v, name).shape, -inf)
            hi[name] = np.full(getattr(v, name).shape, inf)
            lo[name][list(spec.static_knots)] = hi[name][list(spec.static_knots)] = 0.0
    return lo, hi


def build_program(config: CitoConfig, spec: ProgramSpec, body: BodyParams) -> CitoProgram:
    """The whole CITO program for `spec`, built once per solve; `body` carries the
    scene's constants and the planning friction coefficient body.mu."""
    t0 = time.perf_counter()
    prog = MathematicalProgram()
    K = spec.num_knots
    v = CitoVariables.from_prog(prog, K, body.layout.num_fingers)
    rows = KnotRows(body, spec.pinned, spec.c_B, spec.n_B)

    # Dynamics: linear collocation; the nonlinear rows per knot below.
    for a, b in (("x", "xd"), ("xd", "xdd"), ("q", "qd"), ("qd", "qdd")):
        _collocation(prog, getattr(v, a), getattr(v, b), spec.dt)
    # Friction cone, linear: mu lambda_n - lambda_t >= 0 and mu lambda_n + lambda_t >= 0, with the
    # planning friction mu_plan (body.mu), below the scene's mu by search.friction_safety.
    mu, n = body.mu, K * body.layout.num_fingers
    i = np.arange(n)  # [[mu I, -I], [mu I, I]], built directly (as for _collocation)
    A = sp.csc_matrix(
        (
            np.concatenate([np.full(2 * n, mu), -np.ones(n), np.ones(n)]),
            (np.concatenate([i, n + i, i, n + i]), np.concatenate([i, i, n + i, n + i])),
        ),
        shape=(2 * n, 2 * n),
    )
    prog.AddLinearConstraint(
        A, np.zeros(2 * n), np.full(2 * n, np.inf), np.concatenate([v.lambda_n.ravel(), v.lambda_t.ravel()])
    )
    lo, hi = _bounds(v, spec, body)
    for name in lo:
        prog.AddBoundingBoxConstraint(lo[name].ravel(), hi[name].ravel(), getattr(v, name).ravel())

    knots = _BatchConstraint(rows, rows.num_rows, body.layout.block.size, rows.sparsities())
    bounds = [rows.bounds(k, spec.clearance[k]) for k in range(K)]
    binding = prog.AddConstraint(
        knots,
        np.concatenate([lower for lower, _ in bounds]),
        np.concatenate([upper for _, upper in bounds]),
        v.stacked().ravel(),
        description="knots",
    )
    binding.evaluator().SetGradientSparsityPattern(knots.sparsity())
    link_binding = _add_link_rows(prog, v, spec, LinkRows(body, K), config.link_clearance) if config.link_rows else None
    finger_binding = (
        _add_finger_rows(prog, v, spec, FingerRows(body, spec.finger_pairs, K), config.link_clearance)
        if spec.finger_pairs
        else None
    )
    _add_costs(prog, v, spec, config)
    return CitoProgram(
        prog=prog,
        variables=v,
        rows=rows,
        spec=spec,
        knot_binding=binding,
        knot_row_offsets=knots.offsets,
        link_binding=link_binding,
        finger_binding=finger_binding,
        build_time_s=time.perf_counter() - t0,
    )


def link_knots(spec: ProgramSpec) -> list[int]:
    """The knots whose object pose or joint angles are free: all but the first (x_0, q_0 fixed)
    and, when both are fixed there (keyframes), the last. The search's nodes keep the links
    clear of the object by its own exact test."""
    return list(range(1, spec.num_knots - 1 if spec.last_knot_fixed else spec.num_knots))


def _add_link_rows(prog, v: CitoVariables, spec: ProgramSpec, rows: LinkRows, clearance: float):
    """links.py's rows of every knot of `link_knots`, on their pose and joints, as one binding (None: no such knot)."""
    knots = link_knots(spec)
    if not knots:
        return None
    blocks = np.concatenate([v.x, v.q], axis=1)[knots]  # (knots, link size)
    fixed = [(spec.x0, spec.q0)] + ([(spec.x_end, spec.q_end)] if spec.last_knot_fixed else [])
    lower, upper = rows.bounds(clearance, fixed)
    evaluator = _BatchConstraint(rows, np.full(len(knots), lower.size), rows.link_size, [rows.sparsity()] * len(knots))
    binding = prog.AddConstraint(
        evaluator, np.tile(lower, len(knots)), np.tile(upper, len(knots)), blocks.ravel(), description="links"
    )
    binding.evaluator().SetGradientSparsityPattern(evaluator.sparsity())
    return binding


def _add_finger_rows(prog, v: CitoVariables, spec: ProgramSpec, rows: FingerRows, clearance: float):
    """fingers.py's rows of every knot of `link_knots`, on their joints, as one binding (None: no such knot),
    as _add_link_rows."""
    knots = link_knots(spec)
    if not knots:
        return None
    fixed = [spec.q0] + ([spec.q_end] if spec.last_knot_fixed else []) + list(spec.finger_nodes)
    lower, upper = rows.bounds(clearance, fixed)
    evaluator = _BatchConstraint(rows, np.full(len(knots), lower.size), rows.block_size, [rows.sparsity()] * len(knots))
    binding = prog.AddConstraint(
        evaluator, np.tile(lower, len(knots)), np.tile(upper, len(knots)), v.q[knots].ravel(), description="fingers"
    )
    binding.evaluator().SetGradientSparsityPattern(evaluator.sparsity())
    return binding


def _add_costs(prog, v: CitoVariables, spec: ProgramSpec, config: CitoConfig) -> None:
    """Eq. 11: incremental-goal pose cost, tau'R tau, lambda'L lambda, L1 slack penalty
    (weight_contact_slack for pinned fingers' contact-point slacks, weight_slack for the
    complementarity slacks), plus the acceleration regularization (weight_acceleration)."""
    Q = np.diag(config.weight_pose)
    block = knot_block(v.num_fingers)
    n_tau, n_force, n_acc = block.width("tau"), block.width("lambda_n", "lambda_t"), block.width("xdd", "qdd")
    for k in range(spec.num_knots):
        goals = np.asarray(spec.goal_poses[k], dtype=float).reshape(-1, 3)
        if len(goals):
            # sum_j (x - g_j)' Q (x - g_j) = x' (n Q) x - 2 (Q sum_j g_j)' x + sum_j g_j' Q g_j
            prog.AddQuadraticCost(
                2 * len(goals) * Q,
                -2 * Q @ goals.sum(0),
                float(np.einsum("ja,ab,jb->", goals, Q, goals)),
                v.x[k],
                is_convex=True,
            )
        prog.AddQuadraticCost(2 * config.weight_torque * np.eye(n_tau), np.zeros(n_tau), v.tau[k], is_convex=True)
        prog.AddQuadraticCost(
            2 * config.weight_force * np.eye(n_force),
            np.zeros(n_force),
            np.concatenate([v.lambda_n[k], v.lambda_t[k]]),
            is_convex=True,
        )
        slack_weights = np.where(spec.pinned[k], config.weight_contact_slack, config.weight_slack)
        prog.AddLinearCost(slack_weights, 0.0, v.slack[k])
        if config.weight_acceleration > 0:
            prog.AddQuadraticCost(
                2 * config.weight_acceleration * np.eye(n_acc),
                np.zeros(n_acc),
                np.concatenate([v.xdd[k], v.qdd[k]]),
                is_convex=True,
            )


def general_spec(*, x0, q0, object_path, config: CitoConfig, dt: float | None = None) -> ProgramSpec:
    """General CITO (eqs. 1-10, the baselines): every finger free at every knot, fixed
    x_0 and q_0, at rest at the first and last knot, and the incremental goals of the
    object path x*_1..x*_{N-1} over segments of M_hat knots (eq. 11, as the paper's
    baselines use the same cost)."""
    M = config.knots_per_segment
    path = np.asarray(object_path, dtype=float)
    K = (len(path) - 1) * M + 1
    F = len(q0) // 2  # two joints per finger
    goals = [[] for _ in range(K)]
    for s in range(len(path) - 1):
        for k in range(s * M, (s + 1) * M + 1):
            goals[k].append(path[s + 1])
    return ProgramSpec(
        dt=dt or config.dt,
        pinned=np.zeros((K, F), bool),
        c_B=np.zeros((K, F, 2)),
        n_B=np.tile([1.0, 0.0], (K, F, 1)),
        clearance=np.zeros((K, F)),
        x0=np.asarray(x0, float),
        q0=np.asarray(q0, float),
        rest_knots=np.array([0, K - 1]),
        goal_poses=tuple(np.array(g) for g in goals),
        segment_length=M,
    )
