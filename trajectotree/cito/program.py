"""The CITO program builder shared by all three methods (general CITO, eqs. 1-10;
the plan-constrained variant of transition.py only changes the `ProgramSpec`).

Knots k = 0..K-1, dt apart. Linear parts go through Drake's native sparse linear
constraints and bounds: trapezoidal collocation (x_{k+1} = x_k + dt/2 (xd_k + xd_{k+1}),
the same for xd/xdd, q/qd, qd/qdd), the friction cone mu_plan lambda_n >= |lambda_t|,
lambda_n >= 0, slack >= 0, joint and torque limits, fixed x_0 and q_0, rest knots.
The nonlinear rows of a knot (knot.KnotRows) form one Python constraint per knot
with an analytic Jacobian and its sparsity pattern; the link rows (links.LinkRows, unless
`cito.link_rows` is off) another per knot whose pose or joints are free, with a cache of their own,
and so do the finger-finger rows (fingers.FingerRows) of the spec's `finger_pairs`.

Speed: IPOPT evaluates a Python constraint per knot; each call crosses into Python.
All knots are evaluated at once (vectorized) when the first knot asks for its
Jacobian at a full decision vector the cache knows: the one Drake passes to a
visualization callback whenever IPOPT evaluates the cost, or the one the knots'
value calls just assembled (_KnotCache); the other knots' Jacobians are then cache
hits. A knot whose variables match neither is evaluated on its own, so results
never depend on the call order. Trial-point values (asked before the cost) come
from the scalar values_one.
Costs are many small native quadratic costs: Drake differentiates every cost
binding with AutoDiff over its own variables, which is cubic in their number.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

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
    # the fingers whose links the link rows keep off the object (None: every finger)
    link_fingers: tuple | None = None

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
    knot_bindings: list = field(default_factory=list)
    link_bindings: list = field(default_factory=list)  # links.py's rows per free knot ([] when off)
    finger_bindings: list = field(default_factory=list)  # fingers.py's rows per free knot ([] when none)
    build_time_s: float = 0.0


class _KnotCache:
    """All knots' values and Jacobians at one full decision vector (Z, val, jac), evaluated
    in one batch when a knot first asks for it there. The vectors it may evaluate: the one
    Drake passes to the visualization callback at every cost evaluation (`primed`), and
    the knots' latest float-path inputs (`seen`: IPOPT asks for every knot's values at a
    point before its Jacobians there, at the start and after a restoration). Batch rows
    equal one-knot evaluations bit for bit (LinkRows' to rounding: its values_one uses math's exp
    and log), so which vector served a knot never matters."""

    def __init__(self, rows, num_knots: int, width: int):
        self.rows, self.num_knots, self.width = rows, num_knots, width  # rows: KnotRows (its knot size), or LinkRows
        self.Z = self.val = self.jac = None
        self.primed = None
        self.seen = np.full((num_knots, width), np.nan)

    def prime(self, values: np.ndarray) -> None:
        """Visualization callback: remember the vector; rejected trial points are never evaluated."""
        self.primed = np.array(values, dtype=float).reshape(self.num_knots, self.width)

    def _evaluate(self, Z: np.ndarray) -> None:
        self.val, self.jac = self.rows.evaluate(Z, True)
        self.Z = Z

    def primed_rows(self, k: int, z: np.ndarray):
        """Knot k's batch (values, Jacobian) when z is its part of the primed vector, else None."""
        if self.primed is None or not np.array_equal(self.primed[k], z):
            return None
        if self.Z is not self.primed:
            self._evaluate(self.primed)
        return self.val[k], self.jac[k]

    def any_rows(self, k: int, z: np.ndarray):
        """Knot k's batch (values, Jacobian) at z from the evaluated, primed or seen vector, else None."""
        if self.Z is not None and np.array_equal(self.Z[k], z):
            return self.val[k], self.jac[k]
        found = self.primed_rows(k, z)
        if found is None and np.array_equal(self.seen[k], z):
            self._evaluate(self.seen.copy())
            found = self.val[k], self.jac[k]
        return found


class _KnotConstraint:
    """Drake's evaluator for knot k: float input gives values, AutoDiffXd input gives
    values and gradients (analytic Jacobian times the input's gradient). Float values
    are the batch's at the primed vector, else values_one's (the numbers IPOPT has always
    seen: the two differ in the last bit)."""

    def __init__(self, cache: _KnotCache, k: int):
        self.cache, self.k = cache, k
        self.single = cache.rows.knot(k)
        self.n = int(self.single.num_rows[0])

    def _values(self, z: np.ndarray) -> np.ndarray:
        self.cache.seen[self.k] = z
        found = self.cache.primed_rows(self.k, z)
        return found[0][: self.n] if found is not None else self.single.values_one(z)

    def _rows(self, z: np.ndarray):
        found = self.cache.any_rows(self.k, z)
        if found is None:
            found = tuple(a[0] for a in self.single.evaluate(z[None], True))
        return found[0][: self.n], found[1][: self.n]

    def __call__(self, z):
        if z.dtype == object:
            val, jac = self._rows(ExtractValue(z)[:, 0])
            return InitializeAutoDiff(val, jac @ ExtractGradient(z))[:, 0]
        return self._values(np.asarray(z, dtype=float))


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

    cache = _KnotCache(rows, K, body.layout.block.size)
    prog.AddVisualizationCallback(cache.prime, v.stacked().ravel())
    bindings = []
    for k, pattern in enumerate(rows.sparsities()):
        evaluator = _KnotConstraint(cache, k)
        lower, upper = rows.bounds(k, spec.clearance[k])
        binding = prog.AddConstraint(evaluator, lower, upper, v.knot(k), description=f"knot{k}")
        binding.evaluator().SetGradientSparsityPattern(pattern)
        bindings.append(binding)
    link_bindings = (
        _add_link_rows(prog, v, spec, LinkRows(body, K, spec.link_fingers), config.link_clearance)
        if config.link_rows
        else []
    )
    finger_bindings = (
        _add_finger_rows(prog, v, spec, FingerRows(body, spec.finger_pairs, K), config.link_clearance)
        if spec.finger_pairs
        else []
    )
    _add_costs(prog, v, spec, config)
    return CitoProgram(
        prog=prog,
        variables=v,
        rows=rows,
        spec=spec,
        knot_bindings=bindings,
        link_bindings=link_bindings,
        finger_bindings=finger_bindings,
        build_time_s=time.perf_counter() - t0,
    )


def link_knots(spec: ProgramSpec) -> list[int]:
    """The knots whose object pose or joint angles are free: all but the first (x_0, q_0 fixed)
    and, when both are fixed there (keyframes), the last. The search's nodes keep the links
    clear of the object by its own exact test."""
    return list(range(1, spec.num_knots - 1 if spec.last_knot_fixed else spec.num_knots))


def _add_link_rows(prog, v: CitoVariables, spec: ProgramSpec, rows: LinkRows, clearance: float) -> list:
    """links.py's rows, one binding per knot of `link_knots` on its pose and joints, served by
    a cache of their own (primed by a second visualization callback over every knot's x, q)."""
    blocks = np.concatenate([v.x, v.q], axis=1)  # (K, link size)
    cache = _KnotCache(rows, spec.num_knots, rows.link_size)
    prog.AddVisualizationCallback(cache.prime, blocks.ravel())
    fixed = [(spec.x0, spec.q0)] + ([(spec.x_end, spec.q_end)] if spec.last_knot_fixed else [])
    lower, upper = rows.bounds(clearance, fixed)
    pattern = rows.sparsity()
    bindings = []
    for k in link_knots(spec):
        binding = prog.AddConstraint(_KnotConstraint(cache, k), lower, upper, blocks[k], description=f"links{k}")
        binding.evaluator().SetGradientSparsityPattern(pattern)
        bindings.append(binding)
    return bindings


def _add_finger_rows(prog, v: CitoVariables, spec: ProgramSpec, rows: FingerRows, clearance: float) -> list:
    """fingers.py's rows, one binding per knot of `link_knots` on its joints, served by a cache of
    their own (primed by a visualization callback over every knot's q), as _add_link_rows."""
    cache = _KnotCache(rows, spec.num_knots, rows.block_size)
    prog.AddVisualizationCallback(cache.prime, v.q.ravel())
    fixed = [spec.q0] + ([spec.q_end] if spec.last_knot_fixed else []) + list(spec.finger_nodes)
    lower, upper = rows.bounds(clearance, fixed)
    pattern = rows.sparsity()
    bindings = []
    for k in link_knots(spec):
        binding = prog.AddConstraint(_KnotConstraint(cache, k), lower, upper, v.q[k], description=f"fingers{k}")
        binding.evaluator().SetGradientSparsityPattern(pattern)
        bindings.append(binding)
    return bindings


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
