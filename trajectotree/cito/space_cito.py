"""General CITO in space: one IPOPT program over the whole horizon with no contact plan, the plane's baseline
(planning.spatial.plan_space_cito runs it; `plan --method cito|cito-warm`).

Its knots are the segment program's (cito.spatial: R_k = N_k exp([phi_k]x) about a nominal, the same variables,
trapezoidal rule and pair rows, pyramids, motor torques and costs), SPACE_INTERVALS per segment of the search's
path, SPACE_DT apart; the start at rest in the start grasp (pose and joints fixed), the end at rest at the last
nominal with the cube's centre back at the start's. Every finger is free: its force lies in the pyramid about
one face's normal n_B,i per knot (CitoSpec.n_B, fixed before the solve) and acts r below its fingertip centre
along it, at the arm a_i = tip_i - p - r R n_B,i from the centre (T = sum_i a_i x f_i); per finger

    gap_i = d_box(R^T (tip_i - p)) - r >= 0,    gap_i sum_e lambda_i,e <= COMPLEMENTARITY_TOL,

d_box the exact signed distance from the box (geometry.box_signed_distances). Knot rows: F, T, L (9), gaps (F),
products (F), torques (F n), links (F L, solved again with them when a link reaches over 1 mm into the box, as a
segment is). The starts: cito_cold_start holds the start grasp along the straight slerp under one rest-to-rest
time law, with the holding LP's forces; cito_warm_start takes a plan's trajectory as the nominal and the guess,
each finger's face the one its fingertip lies over. IPOPT sees one binding per knot and per interval, all of
them evaluated at once per decision vector (_CitoCache).
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import MathematicalProgram
from scipy.optimize import nnls

from trajectotree.cito.space_hand import cross, exp, refine_ik, right_jacobian, skew, stacked, turned
from trajectotree.cito.spatial import (
    NAMES,
    PHI_BOUND,
    PYRAMID_EDGES,
    SPACE_DT,
    SPACE_INTERVALS,
    Layout,
    SpaceSegmentResult,
    SpaceSegmentRows,
    add_costs,
    add_rule,
    link_depth,
    segment_arrays,
    solve_with_link_retry,
    time_law,
)
from trajectotree.config import CitoConfig
from trajectotree.geometry import (
    BOX_FACE_NAMES,
    BOX_FACE_NORMALS,
    box_face_normals,
    box_signed_distance_gradient,
    box_signed_distances,
    quaternion_matrices,
    so3_log,
)
from trajectotree.scene.statics import pyramid_edges
from trajectotree.search.space_tree import space_object_path
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

COMPLEMENTARITY_TOL = 1e-5  # N m, the most normal force times gap: 0.01 N (the check's FORCE_TOL) at 1 mm


@dataclass(frozen=True)
class CitoSpec:
    """What general CITO in space needs (no contact plan): the nominal orientations the corrections phi are
    taken about over the whole horizon, the cube's centre at both ends, the start grasp's joints and the face
    each finger's force acts on at each knot (its cone's normal)."""

    N: np.ndarray  # (K, 3, 3) nominal orientations: N[0] the start's, N[-1] the end's (phi is 0 there)
    w_nominal: np.ndarray  # (K, 3) rad/s, the nominal's angular velocity in W
    p: np.ndarray  # (3,) m, the cube's centre at the first and the last knot
    q0: np.ndarray  # (F, n) rad, the start grasp (the first knot's joints)
    n_B: np.ndarray  # (K, F, 3) each finger's face normal in B per knot


class SpaceCitoRows(SpaceSegmentRows):
    """The nonlinear rows of general CITO in space, vectorized over its knots: the segment program's dynamics
    (force F, moment T about the centre, momentum L) and motor torques, no pins; every finger free, its force
    in the pyramid about its knot's face normal (CitoSpec.n_B), acting at its fingertip centre less r times
    that normal; per finger its gap (the exact distance of the tip sphere from the box, >= 0) and the
    complementarity of gap and normal force (product <= COMPLEMENTARITY_TOL); the link rows when `links`.
    Knot rows: F, T, L (9), gaps (F), products (F), torques (F n), links (F L)."""

    def __init__(self, scene, fingers, spec: CitoSpec, mu: float, dt: float, links: bool = False):
        self.scene, self.fingers, self.spec = scene, fingers, spec
        self.hand = stacked(fingers)
        self.links = links
        F, n = scene.num_fingers, len(scene.fingers[0].q_lower)
        self.layout = Layout(F, n, PYRAMID_EDGES)
        self.K, self.h = len(spec.N), dt
        self.N, self.w_nominal, self.n_B = spec.N, spec.w_nominal, spec.n_B
        n_W = np.einsum("kij,kfj->kfi", self.N, self.n_B)
        edges_W = pyramid_edges(n_W.reshape(-1, 3), mu, PYRAMID_EDGES).reshape(self.K, F, PYRAMID_EDGES, 3)
        self.edges_B = np.einsum("kji,kfej->kfei", self.N, edges_W)
        self.pinned = np.zeros((self.K, F), dtype=bool)
        self.gap_row, self.product_row, self.torque_row = 9, 9 + F, 9 + 2 * F
        self.link_row = self.torque_row + F * n
        self.set_object(scene, mu)

    def knots(self, first: int, stop: int) -> SpaceCitoRows:
        """These rows restricted to knots first..stop-1 (a shallow copy: one knot's binding evaluates alone)."""
        part = copy.copy(self)
        part.K = stop - first
        for name in ("N", "w_nominal", "n_B", "edges_B", "pinned"):
            setattr(part, name, getattr(self, name)[first:stop])
        return part

    def contact_points_B(self, tips_B):
        """(K, F, 3) where each force acts, in B: r below the fingertip centre along its face's normal (the point
        the moment rows use)."""
        return tips_B - self.r * self.n_B

    def _gaps(self, x, R, tips):
        """(tips_B (K, F, 3) the fingertip centres in B, gaps (K, F) m of the tip spheres from the box)."""
        tips_B = np.einsum("kji,kfj->kfi", R, tips - x["p"][:, None, :])
        return tips_B, box_signed_distances(self.half, tips_B) - self.r

    def _rows(self, x, R, f_B, f_W, tips, taus):
        arms = tips - x["p"][:, None, :] - self.r * np.einsum("kij,kfj->kfi", R, self.n_B)
        force = x["F"] - f_W.sum(1)
        moment = x["T"] - cross(arms, f_W).sum(1)
        momentum = x["L"] - np.einsum("kij,jl,kml,km->ki", R, self.inertia, R, x["w"]) / self.momentum_unit
        gaps = self._gaps(x, R, tips)[1]
        rows = [force, moment, momentum, gaps, x["lam"].sum(-1) * gaps, taus.reshape(self.K, -1)]
        if self.links:
            rows.append(self._link_rows(x, R)[0].reshape(self.K, -1))
        return np.concatenate(rows, axis=1)

    def knot_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (K, rows): the first knot's gaps and links are the start grasp's (its pose and joints fixed)."""
        F, n = self.layout.num_fingers, self.layout.joints
        L = self.hand.link_joint.shape[-1]
        lo, hi = [], []
        for k in range(self.K):
            gap = np.full(F, 0.0 if k > 0 else -np.inf)
            lo.append(np.concatenate([np.zeros(9), gap, np.full(F, -np.inf), -self.tau_max.reshape(F * n)]))
            hi.append(np.concatenate([np.zeros(9), np.full(F, np.inf), np.full(F, COMPLEMENTARITY_TOL),
                                      self.tau_max.reshape(F * n)]))  # fmt: skip
            if self.links:
                lo[-1] = np.concatenate([lo[-1], self.hand.link_radius.ravel() if k > 0 else np.full(F * L, -np.inf)])
                hi[-1] = np.concatenate([hi[-1], np.full(F * L, np.inf)])
        return np.array(lo), np.array(hi)

    def knot_mask(self) -> np.ndarray:
        """(rows, width) bool: the variables of its own knot each knot row depends on."""
        lay = self.layout
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        L = self.hand.link_joint.shape[-1]
        mask = np.zeros((self.link_row + (F * L if self.links else 0), lay.width), dtype=bool)
        mask[:, lay.slice("phi")] = True
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            mask[row : row + 3, lay.slice(name)] = True
        mask[0:6, lay.slice("lam")] = True
        mask[3:6, lay.slice("p")] = mask[3:6, lay.slice("q")] = True
        mask[6:9, lay.slice("w")] = True
        lam, q = lay.slice("lam").start, lay.slice("q").start
        for i in range(F):
            joints, edges = slice(q + n * i, q + n * (i + 1)), slice(lam + m * i, lam + m * (i + 1))
            for row in (self.gap_row + i, self.product_row + i):
                mask[row, lay.slice("p")] = mask[row, joints] = True
            mask[self.product_row + i, edges] = True
            taus = slice(self.torque_row + n * i, self.torque_row + n * (i + 1))
            mask[taus, joints] = mask[taus, edges] = True
            if self.links:
                rows = slice(self.link_row + L * i, self.link_row + L * (i + 1))
                mask[rows, lay.slice("p")] = mask[rows, joints] = True
        return mask

    def knot_jacobians(self, Z):
        """(knot rows (K, Rk), their Jacobian (K, Rk, width)), analytic as SpaceSegmentRows.jacobians'; the moment
        of finger i's force f at arm a = tip - p - r R n_B: d(a x f) = [a]x df - [f]x da."""
        lay = self.layout
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        x, R, f_B, f_W, n_W, (tips, taus, J_tip, J_C, dtau_dq, axes) = self._knot(Z, True)
        rows = self._rows(x, R, f_B, f_W, tips, taus)
        J_r = right_jacobian(x["phi"])
        phi, p, eye = lay.slice("phi"), lay.slice("p"), np.eye(3)
        Jk = np.zeros(rows.shape + (lay.width,))
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            Jk[:, row : row + 3, lay.slice(name)] = eye
        turned_f, turned_n = turned(R, J_r, f_B), turned(R, J_r, self.n_B)  # (K, F, 3, 3)
        arms = tips - x["p"][:, None, :] - self.r * n_W
        Jk[:, 0:3, phi] = -turned_f.sum(1)
        Jk[:, 3:6, phi] = -(self.r * skew(f_W) @ turned_n + skew(arms) @ turned_f).sum(1)
        Jk[:, 3:6, p] = -skew(f_W.sum(1))
        a = np.einsum("kji,kj->ki", R, x["w"])  # the momentum's columns as SpaceSegmentRows.jacobians'
        Jk[:, 6:9, phi] = R @ (skew(a @ self.inertia) - self.inertia @ skew(a)) @ J_r / self.momentum_unit
        Jk[:, 6:9, lay.slice("w")] = -R @ self.inertia @ np.swapaxes(R, -1, -2) / self.momentum_unit
        edges_W = np.einsum("kij,kfej->kfei", R, self.edges_B)  # (K, F, m, 3)
        tips_B, gaps = self._gaps(x, R, tips)
        g = box_signed_distance_gradient(self.half, tips_B)  # (K, F, 3) d gap / d tips_B
        gR = np.einsum("kfi,kji->kfj", g, R)  # d gap / d tip in W
        g_phi = np.einsum("kfi,kfij->kfj", g, skew(tips_B) @ J_r[:, None])
        normal = x["lam"].sum(-1)  # (K, F) N
        tau_phi = J_C @ turned_f - self.r * cross(f_W[:, :, None, :], axes) @ turned_n
        lam0, q0 = lay.slice("lam").start, lay.slice("q").start
        for i in range(F):
            lam_i, q_i = slice(lam0 + m * i, lam0 + m * (i + 1)), slice(q0 + n * i, q0 + n * (i + 1))
            Jk[:, 0:3, lam_i] = -np.swapaxes(edges_W[:, i], -1, -2)
            Jk[:, 3:6, lam_i] = -np.swapaxes(cross(arms[:, i, None, :], edges_W[:, i]), -1, -2)
            Jk[:, 3:6, q_i] = skew(f_W[:, i]) @ J_tip[:, i]
            gap_q = np.einsum("kj,kjc->kc", gR[:, i], J_tip[:, i])
            for row, scale in ((self.gap_row + i, 1.0), (self.product_row + i, normal[:, i, None])):
                Jk[:, row, q_i] = scale * gap_q
                Jk[:, row, p] = -scale * gR[:, i]
                Jk[:, row, phi] = scale * g_phi[:, i]
            Jk[:, self.product_row + i, lam_i] = gaps[:, i, None]
            tau_rows = slice(self.torque_row + n * i, self.torque_row + n * (i + 1))
            Jk[:, tau_rows, lam_i] = np.einsum("kjc,kec->kje", J_C[:, i], edges_W[:, i])
            Jk[:, tau_rows, q_i] = dtau_dq[:, i]
            Jk[:, tau_rows, phi] = tau_phi[:, i]
        if self.links:
            self._link_block(Jk, x, R, J_r)
        return rows, Jk

    def _link_block(self, Jk, x, R, J_r) -> None:
        lay = self.layout
        F, n, L = lay.num_fingers, lay.joints, self.hand.link_joint.shape[-1]
        _, dq, dp, dphi = self._link_rows(x, R, J_r)
        q0 = lay.slice("q").start
        for i in range(F):
            rows = slice(self.link_row + L * i, self.link_row + L * (i + 1))
            Jk[:, rows, q0 + n * i : q0 + n * (i + 1)] = dq[:, i]
            Jk[:, rows, lay.slice("p")] = dp[:, i]
            Jk[:, rows, lay.slice("phi")] = dphi[:, i]

    def pair_rows(self, Z):
        """(pair rows (K-1, 3), their Jacobians on knot k and k+1 (K-1, 3, width) each)."""
        x = self.split(Z)
        R = self.rotations(x["phi"])
        return (self.pair_values(Z), *self._pair_jacobians(x, R, right_jacobian(x["phi"])))


class _CitoCache:
    """Every knot's and pair's rows at one full decision vector, evaluated at once when a binding first asks for
    them there: the vector Drake passes to a visualization callback whenever IPOPT evaluates the cost (as
    cito.program's _KnotCache). A binding whose input is not that vector's part is evaluated on its own."""

    def __init__(self, rows: SpaceCitoRows):
        self.rows = rows
        self.primed = self.Z = self.knot = self.pair = None

    def prime(self, values) -> None:
        self.primed = np.array(values, dtype=float).reshape(self.rows.K, self.rows.layout.width)

    def _batch(self, k: int, stop: int, z: np.ndarray) -> bool:
        if self.primed is None or not np.array_equal(self.primed[k:stop].ravel(), z):
            return False
        if self.Z is not self.primed:
            self.knot = self.rows.knot_jacobians(self.primed)
            self.pair = self.rows.pair_rows(self.primed)
            self.Z = self.primed
        return True

    def knot_rows(self, k: int, z: np.ndarray):
        if self._batch(k, k + 1, z):
            return self.knot[0][k], self.knot[1][k]
        values, J = self.rows.knots(k, k + 1).knot_jacobians(z[None])
        return values[0], J[0]

    def pair_rows(self, k: int, z: np.ndarray):
        found = self._batch(k, k + 2, z)
        values, left, right = self.pair if found else self.rows.knots(k, k + 2).pair_rows(z.reshape(2, -1))
        j = k if found else 0
        return values[j], np.concatenate([left[j], right[j]], axis=1)


class _CitoBinding:
    """Drake's evaluator for one knot's rows (pair False) or one interval's pair rows (pair True), from the
    cache: float input gives the values, AutoDiffXd input values and gradient."""

    def __init__(self, cache: _CitoCache, k: int, pair: bool):
        self.cache, self.k = cache, k
        self.evaluate = cache.pair_rows if pair else cache.knot_rows

    def __call__(self, z):
        if z.dtype == object:
            val, J = self.evaluate(self.k, ExtractValue(z)[:, 0])
            return InitializeAutoDiff(val, J @ ExtractGradient(z))[:, 0]
        return self.evaluate(self.k, np.asarray(z, dtype=float))[0]


@dataclass(frozen=True)
class SpaceCitoProgram:
    prog: MathematicalProgram
    z: np.ndarray  # (K, width)
    rows: SpaceCitoRows
    build_time_s: float


def build_space_cito(scene, fingers, spec: CitoSpec, mu: float, start: np.ndarray, links: bool = False):
    """General CITO's program in space (SpaceCitoRows), from the knots' values `start` (K, width): the rule's
    linear rows and the pair rows between knots, the start at rest in the start grasp (pose and joints fixed),
    the end at rest at the last nominal (phi 0) with the cube's centre back at spec.p, the forces in their
    pyramids, the joints within their limits, the costs of the segment program."""
    t0 = time.perf_counter()
    rows = SpaceCitoRows(scene, fingers, spec, mu, SPACE_DT, links)
    lay, K, W = rows.layout, rows.K, rows.layout.width
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, W, "z")
    var = {name: z[:, lay.slice(name)] for name in (*NAMES, "lam", "q")}
    add_rule(prog, var, rows, scene.object.mass)
    prog.AddBoundingBoxConstraint(-PHI_BOUND, PHI_BOUND, var["phi"][1:-1].ravel())
    for name, value in (("phi", np.zeros(3)), ("p", spec.p), ("w", np.zeros(3)), ("v", np.zeros(3))):
        prog.AddBoundingBoxConstraint(value, value, var[name][0])
        prog.AddBoundingBoxConstraint(value, value, var[name][-1])
    prog.AddBoundingBoxConstraint(0.0, np.inf, var["lam"].ravel())
    lower = np.concatenate([c.q_lower for c in scene.fingers])
    upper = np.concatenate([c.q_upper for c in scene.fingers])
    prog.AddBoundingBoxConstraint(np.tile(lower, K - 1), np.tile(upper, K - 1), var["q"][1:].ravel())
    prog.AddBoundingBoxConstraint(spec.q0.ravel(), spec.q0.ravel(), var["q"][0])
    cache = _CitoCache(rows)
    prog.AddVisualizationCallback(cache.prime, z.ravel())
    lo, hi = rows.knot_bounds()
    knot_pattern = list(zip(*np.nonzero(rows.knot_mask())))
    for k in range(K):
        binding = prog.AddConstraint(_CitoBinding(cache, k, False), lo[k], hi[k], z[k], description=f"knot{k}")
        binding.evaluator().SetGradientSparsityPattern([(int(r), int(c)) for r, c in knot_pattern])
    pair = np.concatenate([rows.pair_mask()] * 2, axis=1)
    pair_pattern = [(int(r), int(c)) for r, c in zip(*np.nonzero(pair))]
    for k in range(K - 1):
        binding = prog.AddConstraint(
            _CitoBinding(cache, k, True), np.zeros(3), np.zeros(3), z[k : k + 2].ravel(), description=f"pair{k}"
        )
        binding.evaluator().SetGradientSparsityPattern(pair_pattern)
    add_costs(prog, var, lay, K)
    prog.SetInitialGuess(z, start)
    return SpaceCitoProgram(prog, z, rows, time.perf_counter() - t0)


def solve_space_cito(scene, fingers, spec: CitoSpec, mu: float, config: CitoConfig, start) -> SpaceSegmentResult:
    """General CITO in space built and solved by IPOPT (cito.solve's options) from `start` (K, width); as the
    segments are, again with the link rows from the solution when a link then reaches over 1 mm into the box."""
    program, result, Z, times = solve_with_link_retry(
        lambda links, Z: build_space_cito(scene, fingers, spec, mu, Z, links),
        lambda program, Z: link_depth(program.rows, Z),
        config,
        np.asarray(start, dtype=float),
    )
    return segment_arrays(program.rows, Z, result, times)


def cito_knots(rows: SpaceCitoRows, p, v, q, f_W) -> np.ndarray:
    """The knots' values (K, width) at the nominal (phi 0) with the cube's centres p (K, 3) and velocities v
    (K, 3), the joints q (K, F, n) and each finger's force f_W (K, F, 3) as the nearest mix of its pyramid's
    edges (non-negative least squares); w the nominal's, F, T, L from them."""
    lay, K = rows.layout, rows.K
    Z = np.zeros((K, lay.width))
    Z[:, lay.slice("p")], Z[:, lay.slice("v")], Z[:, lay.slice("w")] = p, v, rows.w_nominal
    Z[:, lay.slice("q")] = q.reshape(K, -1)
    edges_W = np.einsum("kij,kfej->kfei", rows.N, rows.edges_B)
    lam = np.array([[nnls(edges_W[k, i].T, f_W[k, i])[0] for i in range(lay.num_fingers)] for k in range(K)])
    Z[:, lay.slice("lam")] = lam.reshape(K, -1)
    x = rows.split(Z)
    tips = rows.hand.chain(x["q"])[2]
    f = np.einsum("kfe,kfei->kfi", lam, edges_W)
    arms = tips - p[:, None, :] - rows.r * np.einsum("kij,kfj->kfi", rows.N, rows.n_B)
    Z[:, lay.slice("F")], Z[:, lay.slice("T")] = f.sum(1), cross(arms, f).sum(1)
    Z[:, lay.slice("L")] = (
        np.einsum("kij,jl,kml,km->ki", rows.N, rows.inertia, rows.N, rows.w_nominal) / rows.momentum_unit
    )
    return Z


def cito_cold_start(scene, fingers, node, goal_quaternion, mu: float):
    """(CitoSpec, knots' values (K, width)) of general CITO from the start grasp `node` (a SpaceContactNode) to
    the goal: the nominal is the straight slerp under one rest-to-rest time law (time_law) over as many segments
    as the search's path has (search.space_tree.space_object_path), and the guess the start grasp held: each fingertip
    kept on its contact as the cube turns (refine_ik, within the limits), the forces of the holding LP."""
    segments = len(space_object_path(goal_quaternion, node.object_pose)) - 1
    K = segments * SPACE_INTERVALS + 1
    R_a = quaternion_matrices(node.object_pose[:4])
    axis_angle = so3_log(quaternion_matrices(goal_quaternion) @ R_a.T)
    s, rate = time_law(K - 1)
    N = exp(s[:, None] * axis_angle) @ R_a
    p = np.array(node.object_pose[4:], dtype=float)
    normals = {name: n for name, n in zip(BOX_FACE_NAMES, BOX_FACE_NORMALS)}
    n_B = np.array([normals[f] for f in node.faces])
    centres_B = node.p_BC + scene.tip_radius * n_B
    targets = p + np.einsum("kij,fj->kfi", N, centres_B)
    q = np.empty((K, scene.num_fingers, len(scene.fingers[0].q_lower)))
    for i, (finger, chain) in enumerate(zip(fingers, scene.fingers)):
        q[:, i] = refine_ik(finger, np.tile(node.q[i], (K, 1)), targets[:, i], chain.q_lower, chain.q_upper)
    spec = CitoSpec(N=N, w_nominal=rate[:, None] * axis_angle / SPACE_DT, p=p, q0=q[0], n_B=np.tile(n_B, (K, 1, 1)))
    rows = SpaceCitoRows(scene, fingers, spec, mu, SPACE_DT)
    f_W = np.stack([_holding_forces(rows, k, q[k]) for k in range(K)])
    return spec, cito_knots(rows, np.tile(p, (K, 1)), np.zeros((K, 3)), q, f_W)


def _holding_forces(rows: SpaceCitoRows, k: int, q) -> np.ndarray:
    """(F, 3) N: the forces in W with which all fingers, at q (F, n) on the faces of knot k, hold the cube at rest
    at the nominal with the least largest joint torque (search.stance's holding LP; zero where none holds)."""
    lay, scene = rows.layout, rows.scene
    R = rows.N[k]
    tips = rows.hand.chain(q)[2]
    n_W = rows.n_B[k] @ R.T
    p_WC = tips - rows.r * n_W - rows.spec.p
    edges = rows.edges_B[k] @ R.T  # (F, m, 3)
    W = np.concatenate([edges, np.cross(p_WC[:, None, :], edges)], -1).reshape(-1, 6).T
    J = np.array([scene.fingers[i].jacobian(q[i], -rows.r * n) for i, n in enumerate(n_W)])
    A = spatial_torque_rows(J, n_W, rows.mu, lay.edges)
    tau_g = np.array([rows.fingers[i].torques(q[i], np.zeros(3), np.zeros(3), rows.g)[1] for i in range(len(q))])
    weight = np.r_[0.0, 0.0, scene.object.mass * rows.g, 0.0, 0.0, 0.0]
    _, lam = SpatialHoldingLp(lay.num_fingers, lay.edges, lay.joints).solve(W, A, tau_g, weight)
    return np.einsum("fe,fei->fi", lam.reshape(lay.num_fingers, lay.edges), edges)


def cito_warm_start(scene, fingers, trajectory, mu: float):
    """(CitoSpec, knots' values (K, width)) of general CITO warm-started from a plan's trajectory
    (results.SpaceTrajectory, e.g. TrajectoTree's): its orientations are the nominal, its knots the guess, each
    finger's face per knot the one its fingertip lies over in the plan (the face whose plane it is farthest
    outside of: geometry.box_face_normals), so that a plan's switch of face happens where the plan's does."""
    N = quaternion_matrices(trajectory.x[:, :4])
    p = trajectory.x[:, 4:]
    K, F = trajectory.f_W.shape[:2]
    tips_B = np.einsum("kji,kfj->kfi", N, trajectory.p_W_tip - p[:, None, :])
    q = trajectory.q.reshape(K, F, -1)
    spec = CitoSpec(
        N=N, w_nominal=trajectory.v[:, :3], p=p[0].copy(), q0=q[0], n_B=box_face_normals(scene.object.half, tips_B)
    )
    rows = SpaceCitoRows(scene, fingers, spec, mu, SPACE_DT)
    return spec, cito_knots(rows, p, trajectory.v[:, 3:], q, trajectory.f_W)
