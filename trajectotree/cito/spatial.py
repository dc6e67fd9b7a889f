"""Trajectory optimization in space: the keyframes formulation for a hand in space, one IPOPT program
(Drake MathematicalProgram) per segment between two nodes of the contact search (contact_plan.SpaceContactPlan).

Knots k = 0..N, h apart. The object's orientation is R_k = N_k exp([phi_k]x): N_k the segment's nominal,
a slerp from node a's orientation to node b's with a smooth rest-to-rest time law, composed with a small
rotation vector phi_k (|phi_k,i| <= PHI_BOUND). No unit-norm constraint is needed: phi is a chart of SO(3)
that is smooth and one-to-one within pi of N_k, and the bound keeps it far from there (a quaternion would
add a nonlinear equality per knot). Per knot the variables are

    phi, p (m), w, v (the angular and linear velocity in W), F, T (the fingers' total force and moment about
    the centre, in W), L (the angular momentum R I_B R^T w, W), lambda (each finger's m pyramid-edge
    magnitudes, N: its force on the object f_B = sum_e lambda_e e_e in B), q (rad, finger-major).

The rule between knots is results.SPACE_INTEGRATION (trapezoidal), which the physics check redoes:
linear rows p[k+1] - p[k] = h v_mid, m (v[k+1] - v[k]) = h (F_mid + m g), L[k+1] - L[k] = h T_mid; one
nonlinear pair row per interval, vee(Q - Q^T) / 2 = 0 with Q = exp(-[h w_mid]x) R[k+1] R[k]^T (zero iff
the rule holds, the rotations being far below pi); nonlinear knot rows F = R sum_i f_B,i,
T = R sum_i p_BC,i x f_B,i, L = R I_B R^T w; each pinned fingertip centre on its contact
(p + R (p_BC + r n_B), fixed in B); the joint torques of a quasi-static hand (the fingers' own weight and
J_C^T f at the contact point; the fingers' inertia left out, 2-3 orders below the motors at these speeds)
within the motors; the switching finger's centre at least r + clearance sin(pi k / N) off the box while lifted.
Complementarity by construction: the switching finger's lambda is zero on the interior knots, and it is
pinned to its old contact at k = 0 and its new one at k = N. The ends are the nodes: pose, joints (refined
by Newton's method to the contacts exactly) and rest. The costs are small quadratic ones: the forces, the
joints' steps and phi.

The Jacobian: lambda enters linearly (analytic); every other column by complex-step differentiation of the
vectorized rows (exact to rounding), all knots of one parity at once (a pair row meets one knot of each parity).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import IpoptSolver, MathematicalProgram

from trajectotree.cito.solve import ipopt_options
from trajectotree.config import CitoConfig
from trajectotree.geometry import (
    BOX_FACE_NAMES,
    BOX_FACE_NORMALS,
    box_signed_distances,
    matrix_quaternions,
    quaternion_matrices,
    so3_log,
)
from trajectotree.scene.statics import pyramid_edges
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

PHI_BOUND = 0.3  # rad, each component of the correction to the nominal (the nominal segment turns <= 20 deg)
SPACE_INTERVALS = 10  # knots per segment - 1
SPACE_DT = 0.1  # s between knots: a segment lasts 1 s
PYRAMID_EDGES = 8  # as the search's stances
SWITCH_CLEARANCE = 0.01  # m, the lifted fingertip's least gap at mid-segment (sin profile, as in the plane)
WEIGHT_FORCE = 0.01  # per N^2 of edge magnitude
WEIGHT_JOINT_STEP = 1.0  # per rad^2 of joint motion between knots
WEIGHT_PHI = 1.0  # per rad^2 of correction
COMPLEX_STEP = 1e-30
NEWTON_ITERATIONS = 50  # IK refinements of a fingertip onto its target (damped Newton, converges in ~5)

# Column layout of a knot's variables.
_NAMES = ("phi", "p", "w", "v", "F", "T", "L")


@dataclass(frozen=True)
class _Layout:
    num_fingers: int
    joints: int
    edges: int

    def slice(self, name: str) -> slice:
        if name in _NAMES:
            i = _NAMES.index(name)
            return slice(3 * i, 3 * i + 3)
        lam = 3 * len(_NAMES) + self.num_fingers * self.edges
        if name == "lam":
            return slice(3 * len(_NAMES), lam)
        return slice(lam, lam + self.num_fingers * self.joints)  # q

    @property
    def width(self) -> int:
        return 3 * len(_NAMES) + self.num_fingers * (self.edges + self.joints)


# -- complex-safe kinematics ------------------------------------------------------------------------
def _skew(v):
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
         np.stack([-v[..., 1], v[..., 0], z], -1)],
        axis=-2,
    )  # fmt: skip


def _exp(phi):
    """exp([phi]x) (..., 3, 3) for real or complex-stepped phi (..., 3) (Rodrigues, series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = np.real(theta2) < 1e-10
    t2 = np.where(small, 1.0, theta2)
    theta = np.sqrt(t2)
    a = np.where(small, 1.0 - theta2 / 6 + theta2**2 / 120, np.sin(theta) / theta)
    b = np.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - np.cos(theta)) / t2)
    K = _skew(phi)
    return np.eye(3) + a * K + b * (K @ K)


def _cross(a, b):
    """a x b over the last axis (numpy's cross costs more in axis handling than in arithmetic on these sizes)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def _rotate(axis, angle, v):
    """v (..., M, 3) turned by angle (...) about the unit axis (..., 3) (Rodrigues)."""
    a = axis[..., None, :]
    c, s = np.cos(angle)[..., None, None], np.sin(angle)[..., None, None]
    return v * c + _cross(a, v) * s + a * np.sum(a * v, -1)[..., None] * (1 - c)


@dataclass(frozen=True)
class _Finger:
    """A finger's chain at zero angles (scene.kinematics.SerialFinger) and its links' masses and centres of
    mass (link j beyond joint j), for complex-safe forward kinematics and gravity torques."""

    p_W_joint: np.ndarray  # (n, 3)
    a_W: np.ndarray  # (n, 3)
    p_W_tip0: np.ndarray  # (3,)
    p_W_com0: np.ndarray  # (n, 3)
    mass: np.ndarray  # (n,) kg

    def chain(self, q):
        """(points (..., n, 3), axes (..., n, 3), tip (..., 3), centres of mass (..., n, 3)) at q (..., n):
        joint j turns the joints beyond it, the tip and the links from j on about its current axis."""
        n = len(self.a_W)
        shape = q.shape[:-1]
        # rows: joint points 0..n-1, tip, centres of mass 0..n-1 (points); axes apart (directions)
        P = np.broadcast_to(
            np.concatenate([self.p_W_joint, self.p_W_tip0[None], self.p_W_com0]), shape + (2 * n + 1, 3)
        )
        A = np.broadcast_to(self.a_W, shape + (n, 3))
        P, A = P.astype(np.result_type(q, float)), A.astype(np.result_type(q, float))
        for j in range(n):
            c, a = P[..., j, :], A[..., j, :]
            moving = np.r_[j + 1 : n + 1, n + 1 + j : 2 * n + 1]  # joints beyond j, the tip, links j..n-1
            P[..., moving, :] = c[..., None, :] + _rotate(a, q[..., j], P[..., moving, :] - c[..., None, :])
            A[..., j + 1 :, :] = _rotate(a, q[..., j], A[..., j + 1 :, :])
        return P[..., :n, :], A, P[..., n, :], P[..., n + 1 :, :]

    def torques(self, q, f_W, p_FC_W, gravity: float):
        """(tip (..., 3), tau (..., n)): the motors' torques that hold the finger still against its weight and
        push with f_W (..., 3) at the point p_FC_W (..., 3) from the tip centre (quasi-static)."""
        points, axes, tip, coms = self.chain(q)
        lever = tip + p_FC_W
        push = np.sum(_cross(axes, lever[..., None, :] - points) * f_W[..., None, :], -1)
        # joint j carries links j..n-1: tau_j = sum_l m_l g e_z . (a_j x (c_l - p_j))
        moment = _cross(axes[..., :, None, :], coms[..., None, :, :] - points[..., :, None, :])[..., 2]
        n = len(self.mass)
        beyond = np.triu(np.ones((n, n)))  # [j, l]: link l is beyond joint j
        weight = gravity * np.sum(moment * beyond * self.mass, -1)
        return tip, push + weight


def space_fingers(scene) -> tuple[_Finger, ...]:
    """Each finger's chain and its links' masses and centres of mass at zero angles, from the plant."""
    plant = scene.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, scene.positions(np.r_[1.0, 0, 0, 0, 0, 0, 0], np.zeros(scene.hand_q_indices.size)))
    out = []
    for chain, entry in zip(scene.fingers, scene.hand_file.fingers):
        bodies = [plant.GetJointByName(n, scene.hand).child_body() for n in entry.joints]
        coms = [b.EvalPoseInWorld(context) @ b.CalcCenterOfMassInBodyFrame(context) for b in bodies]
        out.append(
            _Finger(
                p_W_joint=chain.p_W_joint,
                a_W=chain.a_W,
                p_W_tip0=chain.p_W_tip0,
                p_W_com0=np.array(coms),
                mass=np.array([b.get_mass(context) for b in bodies]),
            )
        )
    return tuple(out)


def refine_ik(finger, q0, target, lower, upper) -> np.ndarray:
    """Joint angles (..., n) near q0 that put the fingertip centre on `target` (..., 3): damped Newton steps
    within the limits (the nodes' IK holds the tips to 0.1 mm; the program pins them exactly)."""
    q = np.array(q0, dtype=float)
    for _ in range(NEWTON_ITERATIONS):
        points, axes, tip, _ = finger.chain(q)
        error = target - tip
        if np.max(np.abs(error)) < 1e-13:
            break
        J = np.swapaxes(_cross(axes, tip[..., None, :] - points), -1, -2)  # (..., 3, n)
        JJt = J @ np.swapaxes(J, -1, -2) + 1e-8 * np.eye(3)
        q = np.clip(q + np.einsum("...ji,...j->...i", J, np.linalg.solve(JJt, error[..., None])[..., 0]), lower, upper)
    return q


# -- a segment --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SegmentSpec:
    """What one segment's program needs: its two nodes' poses and joints, the contacts (in B) and who moves."""

    R_a: np.ndarray  # (3, 3)
    R_b: np.ndarray  # (3, 3)
    p: np.ndarray  # (3,) m, the object's centre (kept)
    q_a: np.ndarray  # (F, n) rad
    q_b: np.ndarray  # (F, n) rad
    p_BC_a: np.ndarray  # (F, 3) m, the contacts at node a (in B)
    p_BC_b: np.ndarray  # (F, 3) m, at node b: node a's but the switching finger's
    n_B_a: np.ndarray  # (F, 3)
    n_B_b: np.ndarray  # (F, 3)
    switching: int | None


def segment_spec(scene, fingers, node_a, node_b) -> SegmentSpec:
    """The segment between two nodes of a SpaceContactPlan, the nodes' joints refined onto their contacts."""
    r = scene.tip_radius
    normals = {name: n for name, n in zip(BOX_FACE_NAMES, BOX_FACE_NORMALS)}
    out = {}
    for key, node in (("a", node_a), ("b", node_b)):
        R = quaternion_matrices(node.object_pose[:4])
        n_B = np.array([normals[f] for f in node.faces])
        targets = node.object_pose[4:] + (node.p_BC + r * n_B) @ R.T
        q = np.array(
            [
                refine_ik(f, node.q[i], targets[i], c.q_lower, c.q_upper)
                for i, (f, c) in enumerate(zip(fingers, scene.fingers))
            ]
        )
        out[key] = (R, q, np.array(node.p_BC, dtype=float), n_B)
    return SegmentSpec(
        R_a=out["a"][0],
        R_b=out["b"][0],
        p=np.array(node_a.object_pose[4:], dtype=float),
        q_a=out["a"][1],
        q_b=out["b"][1],
        p_BC_a=out["a"][2],
        p_BC_b=out["b"][2],
        n_B_a=out["a"][3],
        n_B_b=out["b"][3],
        switching=node_b.switching_finger,
    )


def time_law(intervals: int) -> tuple[np.ndarray, np.ndarray]:
    """(s (K,), s_dot (K,) 1/s per unit h): a rest-to-rest law from 0 to 1 whose knots the trapezoidal rule
    integrates exactly (s_dot ~ sin^2(pi k / N)), so that the nominal with phi = 0 keeps the rule."""
    rate = np.sin(np.pi * np.arange(intervals + 1) / intervals) ** 2
    steps = 0.5 * (rate[1:] + rate[:-1])
    total = steps.sum()
    return np.concatenate([[0.0], np.cumsum(steps)]) / total, rate / total


class SpaceSegmentRows:
    """The nonlinear rows of one segment's program, vectorized over its knots (see the module's doc)."""

    def __init__(self, scene, fingers, spec: SegmentSpec, mu: float, intervals: int, dt: float):
        self.scene, self.fingers, self.spec = scene, fingers, spec
        F, n = scene.num_fingers, len(scene.fingers[0].q_lower)
        self.layout = _Layout(F, n, PYRAMID_EDGES)
        self.K, self.h = intervals + 1, dt
        s, self.rate = time_law(intervals)
        self.axis_angle = so3_log(spec.R_b @ spec.R_a.T)  # W: the nominal turns about this at a fixed axis
        self.N = _exp(s[:, None] * self.axis_angle) @ spec.R_a  # (K, 3, 3) nominal orientations
        self.w_nominal = self.rate[:, None] * self.axis_angle / dt  # rad/s: the rule holds at phi = 0
        # contacts per knot (in B): node a's, the switching finger's new one at the last knot
        self.p_BC = np.repeat(spec.p_BC_a[None], self.K, axis=0)
        self.n_B = np.repeat(spec.n_B_a[None], self.K, axis=0)
        if spec.switching is not None:
            self.p_BC[-1, spec.switching], self.n_B[-1, spec.switching] = (
                spec.p_BC_b[spec.switching],
                spec.n_B_b[spec.switching],
            )
        self.edges_B = pyramid_edges(self.n_B.reshape(-1, 3), mu, PYRAMID_EDGES).reshape(self.K, F, PYRAMID_EDGES, 3)
        self.pinned = np.ones((self.K, F), dtype=bool)
        self.clearance = np.zeros(self.K)
        if spec.switching is not None:
            self.pinned[1:-1, spec.switching] = False
            self.clearance = SWITCH_CLEARANCE * np.sin(np.pi * np.arange(self.K) / intervals)
        self.inertia = scene.object.mass * np.diag(
            [sum(np.square(scene.object.size)) - e * e for e in scene.object.size]
        ) / 12  # fmt: skip
        self.half = scene.object.half
        self.r, self.g = scene.tip_radius, scene.gravity
        self.tau_max = scene.tau_max
        self.mu = mu

    # -- values ------------------------------------------------------------------------------------
    def split(self, Z):
        lay = self.layout
        parts = {name: Z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
        parts["lam"] = parts["lam"].reshape(self.K, lay.num_fingers, lay.edges)
        parts["q"] = parts["q"].reshape(self.K, lay.num_fingers, lay.joints)
        return parts

    def rotations(self, phi):
        return self.N @ _exp(phi)

    def forces_B(self, lam):
        """(K, F, 3) each finger's force on the object in B."""
        return np.einsum("kfe,kfec->kfc", lam, self.edges_B)

    def knot_values(self, Z):
        """(rows (K, 9 + 7F): F, T, L balance, fingertip pins (3F), torques (3F... n F), clearance (1)),
        and the joint torques (K, F, n), the fingertip centres (K, F, 3)."""
        x = self.split(Z)
        R = self.rotations(x["phi"])
        f_B = self.forces_B(x["lam"])
        f_W = np.einsum("kij,kfj->kfi", R, f_B)
        force = x["F"] - f_W.sum(1)
        moment = x["T"] - np.einsum("kij,kj->ki", R, np.cross(self.p_BC, f_B).sum(1))
        momentum = x["L"] - np.einsum("kij,jl,kml,km->ki", R, self.inertia, R, x["w"])
        n_W = np.einsum("kij,kfj->kfi", R, self.n_B)
        tips, taus = [], []
        for i, finger in enumerate(self.fingers):
            tip, tau = finger.torques(x["q"][:, i], f_W[:, i], -self.r * n_W[:, i], self.g)
            tips.append(tip)
            taus.append(tau)
        tips, taus = np.stack(tips, 1), np.stack(taus, 1)
        targets = x["p"][:, None, :] + np.einsum("kij,kfj->kfi", R, self.p_BC + self.r * self.n_B)
        pins = (tips - targets).reshape(self.K, -1)
        clearance = np.zeros(self.K, dtype=Z.dtype)
        if self.spec.switching is not None:
            p_B = np.einsum("kji,kj->ki", R, tips[:, self.spec.switching] - x["p"])
            d = p_B * np.where(np.real(p_B) < 0, -1.0, 1.0) - self.half
            out = np.where(np.real(d) > 0, d, 0.0)
            clearance = np.sum(out * out, -1)
        rows = np.concatenate([force, moment, momentum, pins, taus.reshape(self.K, -1), clearance[:, None]], axis=1)
        return rows, taus, tips

    def pair_values(self, Z):
        """(K - 1, 3): vee(Q - Q^T) / 2, Q = exp(-[h w_mid]x) R[k+1] R[k]^T."""
        x = self.split(Z)
        R = self.rotations(x["phi"])
        w_mid = 0.5 * (x["w"][1:] + x["w"][:-1])
        Q = _exp(-self.h * w_mid) @ R[1:] @ np.swapaxes(R[:-1], -1, -2)
        return 0.5 * np.stack([Q[:, 2, 1] - Q[:, 1, 2], Q[:, 0, 2] - Q[:, 2, 0], Q[:, 1, 0] - Q[:, 0, 1]], -1)

    def knot_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        F = self.layout.num_fingers
        n = self.layout.joints
        lo, hi = [], []
        for k in range(self.K):
            pin = np.where(np.repeat(self.pinned[k], 3), 0.0, np.inf)
            gap = (self.r + self.clearance[k]) ** 2 if self.clearance[k] > 0 else -np.inf
            lo.append(np.concatenate([np.zeros(9), -pin, -self.tau_max.reshape(F * n), [gap]]))
            hi.append(np.concatenate([np.zeros(9), pin, self.tau_max.reshape(F * n), [np.inf]]))
        return np.array(lo), np.array(hi)

    # -- the Jacobian ------------------------------------------------------------------------------
    def jacobians(self, Z):
        """(knot rows (K, Rk), their Jacobian (K, Rk, width); pair rows (K-1, 3), Jacobians on knot k and
        k+1 (K-1, 3, width) each). Complex steps: a knot row meets its own knot's variables alone, so a column
        is stepped at every knot at once, and finger i's rows meet only finger i's joints, so joint j of every
        finger at once; a pair row meets knots k and k+1, so phi and w are stepped at one parity at a time.
        F, T and L enter their rows with the identity, v no knot row, lambda linearly (_lambda_columns)."""
        lay = self.layout
        rows, _, _ = self.knot_values(Z)
        pair = self.pair_values(Z)
        Jk = np.zeros(rows.shape + (lay.width,))
        Jl = np.zeros(pair.shape + (lay.width,))
        Jr = np.zeros(pair.shape + (lay.width,))
        q0, F, n = lay.slice("q").start, lay.num_fingers, lay.joints
        groups = [[c] for name in ("phi", "p", "w") for c in range(lay.slice(name).start, lay.slice(name).stop)]
        groups += [[q0 + i * n + j for i in range(F)] for j in range(n)]
        for group in groups:
            Zc = Z.astype(complex)
            Zc[:, group] += 1j * COMPLEX_STEP
            d = np.imag(self.knot_values(Zc)[0]) / COMPLEX_STEP
            if len(group) == 1:
                Jk[:, :, group[0]] = d
                continue
            for i, c in enumerate(group):  # finger i's joint: its pins, torques and (switching) clearance
                mine = np.r_[9 + 3 * i : 12 + 3 * i, 9 + 3 * F + n * i : 9 + 3 * F + n * (i + 1)]
                if i == self.spec.switching:
                    mine = np.r_[mine, rows.shape[1] - 1]
                Jk[:, mine, c] = d[:, mine]
        for name in ("F", "T", "L"):
            cols = lay.slice(name)
            row = 3 * ("F", "T", "L").index(name)
            Jk[:, row : row + 3, cols] = np.eye(3)
        parity = np.arange(self.K) % 2
        for c in [*range(3), *range(lay.slice("w").start, lay.slice("w").stop)]:
            for colour in (0, 1):
                Zc = Z.astype(complex)
                Zc[parity == colour, c] += 1j * COMPLEX_STEP
                dp = np.imag(self.pair_values(Zc)) / COMPLEX_STEP
                left = parity[:-1] == colour
                Jl[left, :, c] = dp[left]
                Jr[~left, :, c] = dp[~left]
        self._lambda_columns(Z, Jk)
        return rows, Jk, pair, Jl, Jr

    def _lambda_columns(self, Z, Jk) -> None:
        """The rows' derivatives in lambda, where they are linear: F, T and the torques."""
        lay = self.layout
        x = self.split(Z)
        R = self.rotations(x["phi"])
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        edges_W = np.einsum("kij,kfej->kfei", R, self.edges_B)  # (K, F, m, 3)
        moments_W = np.einsum("kij,kfej->kfei", R, np.cross(self.p_BC[:, :, None, :], self.edges_B))
        n_W = np.einsum("kij,kfj->kfi", R, self.n_B)
        start = lay.slice("lam").start
        tau_row = 9 + 3 * F
        for i, finger in enumerate(self.fingers):
            cols = slice(start + i * m, start + (i + 1) * m)
            Jk[:, 0:3, cols] = -np.swapaxes(edges_W[:, i], -1, -2)
            Jk[:, 3:6, cols] = -np.swapaxes(moments_W[:, i], -1, -2)
            points, axes, tip, _ = finger.chain(x["q"][:, i])
            lever = tip - self.r * n_W[:, i]
            J_C = _cross(axes, lever[:, None, :] - points)  # (K, n, 3): row j is joint j's lever
            Jk[:, tau_row + i * n : tau_row + (i + 1) * n, cols] = np.einsum("kjc,kec->kje", J_C, edges_W[:, i])


class _SegmentConstraint:
    """Drake's evaluator for a segment's nonlinear rows (knot rows, then pair rows) over all its knots'
    variables, knot after knot: float input gives the values, AutoDiffXd input values and gradient."""

    def __init__(self, rows: SpaceSegmentRows):
        self.rows = rows
        K, W = rows.K, rows.layout.width
        self.num_knot_rows = rows.knot_bounds()[0].shape[1]
        self.shape = (K * self.num_knot_rows + 3 * (K - 1), K * W)

    def values(self, Z) -> np.ndarray:
        return np.concatenate([self.rows.knot_values(Z)[0].ravel(), self.rows.pair_values(Z).ravel()])

    def jacobian(self, Z) -> tuple[np.ndarray, np.ndarray]:
        rows, Jk, pair, Jl, Jr = self.rows.jacobians(Z)
        K, W, Rk = self.rows.K, self.rows.layout.width, self.num_knot_rows
        J = np.zeros(self.shape)
        for k in range(K):
            J[k * Rk : (k + 1) * Rk, k * W : (k + 1) * W] = Jk[k]
        base = K * Rk
        for k in range(K - 1):
            J[base + 3 * k : base + 3 * k + 3, k * W : (k + 1) * W] = Jl[k]
            J[base + 3 * k : base + 3 * k + 3, (k + 1) * W : (k + 2) * W] = Jr[k]
        return np.concatenate([rows.ravel(), pair.ravel()]), J

    def sparsity(self) -> list[tuple[int, int]]:
        K, W, Rk = self.rows.K, self.rows.layout.width, self.num_knot_rows
        out = [(k * Rk + r, k * W + c) for k in range(K) for r in range(Rk) for c in range(W)]
        base = K * Rk
        out += [(base + 3 * k + r, k * W + c) for k in range(K - 1) for r in range(3) for c in range(2 * W)]
        return out

    def __call__(self, z):
        W = self.rows.layout.width
        if z.dtype == object:
            val, J = self.jacobian(ExtractValue(z)[:, 0].reshape(-1, W))
            G = ExtractGradient(z)
            identity = G.shape == (J.shape[1],) * 2 and np.count_nonzero(G) == G.shape[0] and np.all(G.diagonal() == 1)
            return InitializeAutoDiff(val, J if identity else J @ G)[:, 0]
        return self.values(np.asarray(z, dtype=float).reshape(-1, W))


@dataclass(frozen=True)
class SpaceSegmentResult:
    """One segment's solve: its knots' values (K, width) and the arrays of its plan."""

    success: bool
    status: str
    iterations: int
    solve_time_s: float
    build_time_s: float
    t: np.ndarray  # (K,) s from the segment's start
    x: np.ndarray  # (K, 7)
    v: np.ndarray  # (K, 6)
    q: np.ndarray  # (K, F n)
    tau: np.ndarray  # (K, F n)
    f_W: np.ndarray  # (K, F, 3)
    p_W_C: np.ndarray  # (K, F, 3)
    p_W_tip: np.ndarray  # (K, F, 3)


def _guess(rows: SpaceSegmentRows) -> np.ndarray:
    """Knot values: the nominal (phi = 0) at rest in position, the holding fingers' joints by Newton's method
    onto their contacts from the nodes' interpolation, the switching finger's along a path lifted off the box,
    and the forces of the holding LP at each knot (quasi-static)."""
    spec, lay, K = rows.spec, rows.layout, rows.K
    Z = np.zeros((K, lay.width))
    Z[:, lay.slice("p")] = spec.p
    Z[:, lay.slice("w")] = rows.w_nominal
    Z[:, lay.slice("L")] = np.einsum("kij,jl,kml,km->ki", rows.N, rows.inertia, rows.N, rows.w_nominal)
    tau_frac = np.linspace(0.0, 1.0, K)[:, None, None]
    q = (1 - tau_frac) * spec.q_a + tau_frac * spec.q_b
    targets = spec.p + np.einsum("kij,kfj->kfi", rows.N, rows.p_BC + rows.r * rows.n_B)
    if spec.switching is not None:
        i = spec.switching
        start = spec.p_BC_a[i] + rows.r * spec.n_B_a[i]
        end = spec.p_BC_b[i] + rows.r * spec.n_B_b[i]
        for k in range(1, K - 1):
            targets[k, i] = spec.p + rows.N[k] @ _lifted(
                start, end, k / (K - 1), rows.half, rows.r + 1.5 * rows.clearance[k]
            )
    for i, (finger, chain) in enumerate(zip(rows.fingers, rows.scene.fingers)):
        q[:, i] = refine_ik(finger, q[:, i], targets[:, i], chain.q_lower, chain.q_upper)
    Z[:, lay.slice("q")] = q.reshape(K, -1)
    stance = [i for i in range(lay.num_fingers) if i != spec.switching]
    lp = SpatialHoldingLp(len(stance), lay.edges, lay.joints)
    weight = np.r_[0.0, 0.0, rows.scene.object.mass * rows.g, 0.0, 0.0, 0.0]
    lam = np.zeros((K, lay.num_fingers, lay.edges))
    for k in range(K):
        n_W = rows.n_B[k, stance] @ rows.N[k].T
        p_WC = rows.p_BC[k, stance] @ rows.N[k].T
        edges = rows.edges_B[k, stance] @ rows.N[k].T  # (k, m, 3)
        W = np.concatenate([edges, np.cross(p_WC[:, None, :], edges)], -1).reshape(-1, 6).T
        J = np.array([rows.scene.fingers[i].jacobian(q[k, i], -rows.r * n) for i, n in zip(stance, n_W)])
        A = spatial_torque_rows(J, n_W, rows.mu, lay.edges)
        tau_g = np.array([rows.fingers[i].torques(q[k, i], np.zeros(3), np.zeros(3), rows.g)[1] for i in stance])
        _, x = lp.solve(W, A, tau_g, weight)
        lam[k, stance] = x.reshape(len(stance), lay.edges)
    Z[:, lay.slice("lam")] = lam.reshape(K, -1)
    f_W = np.einsum("kij,kfj->kfi", rows.N, rows.forces_B(lam))
    Z[:, lay.slice("F")] = f_W.sum(1)
    Z[:, lay.slice("T")] = np.einsum("kij,kj->ki", rows.N, np.cross(rows.p_BC, rows.forces_B(lam)).sum(1))
    return Z


def _lifted(start, end, s: float, half, gap: float) -> np.ndarray:
    """A point (B) on the way from `start` to `end`, pushed out along its ray from the centre until it lies
    `gap` off the box (the box's distance grows along every ray from its centre: bisection)."""
    point = (1 - s) * start + s * end
    lo, hi = 0.0, 10.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if box_signed_distances(half, mid * point) < gap:
            lo = mid
        else:
            hi = mid
    return max(hi, 1.0) * point


def solve_space_segment(scene, fingers, spec: SegmentSpec, mu: float, config: CitoConfig) -> SpaceSegmentResult:
    """One segment's program, built and solved by IPOPT (cito.solve's options) from the guess."""
    t0 = time.perf_counter()
    rows = SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT)
    lay, K = rows.layout, rows.K
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, lay.width, "z")
    var = {name: z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
    h, m = rows.h, scene.object.mass
    eye = np.eye(3)
    for k in range(K - 1):
        # p[k+1] - p[k] - h/2 (v[k] + v[k+1]) = 0, m (v[k+1] - v[k]) - h/2 (F[k] + F[k+1]) = h m g, L likewise
        pk = np.concatenate([var["p"][k], var["p"][k + 1], var["v"][k], var["v"][k + 1]])
        prog.AddLinearEqualityConstraint(np.hstack([-eye, eye, -h / 2 * eye, -h / 2 * eye]), np.zeros(3), pk)
        vk = np.concatenate([var["v"][k], var["v"][k + 1], var["F"][k], var["F"][k + 1]])
        g = np.array([0.0, 0.0, -h * m * rows.g])
        prog.AddLinearEqualityConstraint(np.hstack([-m * eye, m * eye, -h / 2 * eye, -h / 2 * eye]), g, vk)
        lk = np.concatenate([var["L"][k], var["L"][k + 1], var["T"][k], var["T"][k + 1]])
        prog.AddLinearEqualityConstraint(np.hstack([-eye, eye, -h / 2 * eye, -h / 2 * eye]), np.zeros(3), lk)
    prog.AddBoundingBoxConstraint(-PHI_BOUND, PHI_BOUND, var["phi"][1:-1].ravel())
    for name, value in (("phi", np.zeros(3)), ("p", spec.p), ("w", np.zeros(3)), ("v", np.zeros(3))):
        prog.AddBoundingBoxConstraint(value, value, var[name][0])
        prog.AddBoundingBoxConstraint(value, value, var[name][-1])
    # static at the nodes (the fingers' net wrench holds the weight), so that consecutive segments, whose forces
    # at their common node differ, agree on the net wrench there: the joined trajectory keeps the rule
    for end in (0, -1):
        prog.AddBoundingBoxConstraint(np.r_[0.0, 0.0, m * rows.g], np.r_[0.0, 0.0, m * rows.g], var["F"][end])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), var["T"][end])
    lam_hi = np.full((K, lay.num_fingers, lay.edges), np.inf)
    if spec.switching is not None:
        lam_hi[1:-1, spec.switching] = 0.0
    prog.AddBoundingBoxConstraint(np.zeros(lam_hi.size), lam_hi.ravel(), var["lam"].ravel())
    lower = np.concatenate([c.q_lower for c in scene.fingers])
    upper = np.concatenate([c.q_upper for c in scene.fingers])
    prog.AddBoundingBoxConstraint(np.tile(lower, K - 2), np.tile(upper, K - 2), var["q"][1:-1].ravel())
    prog.AddBoundingBoxConstraint(spec.q_a.ravel(), spec.q_a.ravel(), var["q"][0])
    prog.AddBoundingBoxConstraint(spec.q_b.ravel(), spec.q_b.ravel(), var["q"][-1])
    constraint = _SegmentConstraint(rows)
    lo, hi = rows.knot_bounds()
    binding = prog.AddConstraint(
        constraint,
        np.concatenate([lo.ravel(), np.zeros(3 * (K - 1))]),
        np.concatenate([hi.ravel(), np.zeros(3 * (K - 1))]),
        z.ravel(),
        description="space segment",
    )
    binding.evaluator().SetGradientSparsityPattern(constraint.sparsity())
    nq = lay.num_fingers * lay.joints
    for k in range(K):
        prog.AddQuadraticCost(
            2 * WEIGHT_FORCE * np.eye(lay.num_fingers * lay.edges),
            np.zeros(lay.num_fingers * lay.edges),
            var["lam"][k],
            is_convex=True,
        )
        prog.AddQuadraticCost(2 * WEIGHT_PHI * eye, np.zeros(3), var["phi"][k], is_convex=True)
    for k in range(K - 1):
        Q = np.block([[np.eye(nq), -np.eye(nq)], [-np.eye(nq), np.eye(nq)]]) * 2 * WEIGHT_JOINT_STEP
        prog.AddQuadraticCost(Q, np.zeros(2 * nq), np.concatenate([var["q"][k], var["q"][k + 1]]), is_convex=True)
    guess = _guess(rows)
    build = time.perf_counter() - t0
    t1 = time.perf_counter()
    result = IpoptSolver().Solve(prog, guess.ravel(), ipopt_options(config))
    solve_time = time.perf_counter() - t1
    Z = result.GetSolution(z).reshape(K, lay.width)
    return _segment_arrays(rows, Z, result, build, solve_time)


def _segment_arrays(rows: SpaceSegmentRows, Z, result, build: float, solve_time: float) -> SpaceSegmentResult:
    x = rows.split(Z)
    R = rows.rotations(x["phi"])
    _, taus, tips = rows.knot_values(Z)
    f_W = np.einsum("kij,kfj->kfi", R, rows.forces_B(x["lam"]))
    p = x["p"]
    tips_B = np.einsum("kji,kfj->kfi", R, tips - p[:, None, :])
    p_BC = np.where(rows.pinned[..., None], rows.p_BC, np.clip(tips_B, -rows.half, rows.half))
    details = result.get_solver_details()
    return SpaceSegmentResult(
        success=bool(result.is_success()),
        status=details.ConvertStatusToString(),
        iterations=-1,
        solve_time_s=solve_time,
        build_time_s=build,
        t=rows.h * np.arange(rows.K),
        x=np.hstack([matrix_quaternions(R), p]),
        v=np.hstack([x["w"], x["v"]]),
        q=x["q"].reshape(rows.K, -1),
        tau=taus.reshape(rows.K, -1),
        f_W=f_W,
        p_W_C=p[:, None, :] + np.einsum("kij,kfj->kfi", R, p_BC),
        p_W_tip=tips,
    )
