"""Trajectory optimization in space: the keyframes formulation for a hand in space, one IPOPT program
(Drake MathematicalProgram) per segment between two nodes of the contact search (contact_plan.SpaceContactPlan).

Knots k = 0..N, h apart. The object's orientation is R_k = N_k exp([phi_k]x): N_k the segment's nominal,
a slerp from node a's orientation to node b's with a smooth rest-to-rest time law, composed with a small
rotation vector phi_k (|phi_k,i| <= PHI_BOUND). No unit-norm constraint is needed: phi is a chart of SO(3)
that is smooth and one-to-one within pi of N_k, and the bound keeps it far from there (a quaternion would
add a nonlinear equality per knot). Per knot the variables are

    phi, p (m), w, v (the angular and linear velocity in W), F, T (the fingers' total force and moment about
    the centre, in W), L (the angular momentum R I_B R^T w, W, in units of the cube's largest principal
    inertia), lambda (each finger's m pyramid-edge magnitudes, N: its force on the object f_B = sum_e lambda_e e_e
    in B), q (rad, finger-major).

The rule between knots is results.SPACE_INTEGRATION (trapezoidal), which the physics check redoes:
linear rows p[k+1] - p[k] = h v_mid, m (v[k+1] - v[k]) = h (F_mid + m g), L[k+1] - L[k] = h T_mid; one
nonlinear pair row per interval, vee(Q - Q^T) / 2 = 0 with Q = exp(-[h w_mid]x) R[k+1] R[k]^T (zero iff
the rule holds, the rotations being far below pi); nonlinear knot rows F = R sum_i f_B,i,
T = R sum_i p_BC,i x f_B,i, L = R I_B R^T w; each pinned fingertip centre on its contact
(p + R (p_BC + r n_B), fixed in B); the joint torques of a quasi-static hand (cito.space_hand: the fingers' own
weight and J_C^T f at the contact point) within the motors; the switching finger's centre at least
r + clearance sin(pi k / N) off the box while lifted.
The link rows, on demand: a segment whose solution has a link capsule over 1 mm inside the box (the physics
check's limit, results.LINK_PENETRATION_TOL) is solved again from that solution with a row per capsule and free
knot, the signed distance of its axis from the box at least its radius (the nearest point by golden-section
search; 2 of the first 9 seed-0 goals had such a segment, 1.4 and 7 mm deep).
The finger-finger rows (cito.space_fingers): each pair of two fingers' parts (link capsules, fingertip
spheres) that comes within NEAR_MARGIN over the start keeps CLEARANCE apart on the free knots; a solution with
two fingers over 1 mm inside each other is solved again with the pairs near it (the only rows keeping fingers
apart: the switching fingertip's from the others' is one of their pairs).
Complementarity by construction: the switching finger's lambda is zero on the interior knots, and it is
pinned to its old contact at k = 0 and its new one at k = N. The ends are the nodes: pose, joints (refined
by Newton's method to the contacts exactly) and rest. The costs are small quadratic ones: the forces, the
joints' steps and phi.

The Jacobian is analytic and vectorized over knots and fingers, in the sparsity of what each row depends on
(SpaceSegmentRows.jacobians, knot_mask, pair_mask), the rotations' and the fingers' derivatives those of
cito.space_hand. General CITO in space (cito.space_cito) and the joint formulation (cito.space_joint) build their
programs from these rows, the layout and the costs.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import IpoptSolver, MathematicalProgram

from trajectotree.cito.solve import ipopt_options
from trajectotree.cito.space_fingers import (
    CLEARANCE,
    FingerParts,
    SpaceFingerRows,
    least_part_distance,
    near_parts,
)
from trajectotree.cito.space_hand import (
    BASIS_SKEW,
    cross,
    exp,
    refine_ik,
    right_jacobian,
    skew,
    stacked,
    turned,
    vee_skew,
)
from trajectotree.config import CitoConfig
from trajectotree.geometry import (
    BOX_FACE_NAMES,
    BOX_FACE_NORMALS,
    box_signed_distance_gradient,
    box_signed_distances,
    matrix_quaternions,
    quaternion_matrices,
    segment_box_distances,
    segment_box_nearest,
    so3_log,
)
from trajectotree.results import LINK_PENETRATION_TOL
from trajectotree.scene.statics import pyramid_edges
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows

PHI_BOUND = 0.3  # rad, each component of the correction to the nominal (the nominal segment turns <= 20 deg)
SPACE_INTERVALS = 10  # knots per segment - 1
SPACE_DT = 0.1  # s between knots: a segment lasts 1 s
PYRAMID_EDGES = 8  # as the search's stances, turned as theirs (SpaceSegmentRows.edges_B)
SWITCH_CLEARANCE = 0.01  # m, the lifted fingertip's least gap at mid-segment (sin profile, as in the plane)
WEIGHT_FORCE = 0.01  # per N^2 of edge magnitude
WEIGHT_JOINT_STEP = 1.0  # per rad^2 of joint motion between knots
WEIGHT_PHI = 1.0  # per rad^2 of correction
LINK_SEARCH_ITERATIONS = 30  # golden-section steps along a capsule's axis: 0.618^30 = 5e-7 of its length

# Column layout of a knot's variables.
NAMES = ("phi", "p", "w", "v", "F", "T", "L")


@dataclass(frozen=True)
class Layout:
    """A knot's columns: phi, p, w, v, F, T, L (3 each), each finger's edge magnitudes lambda, its joints q."""

    num_fingers: int
    joints: int
    edges: int

    def slice(self, name: str) -> slice:
        if name in NAMES:
            i = NAMES.index(name)
            return slice(3 * i, 3 * i + 3)
        lam = 3 * len(NAMES) + self.num_fingers * self.edges
        if name == "lam":
            return slice(3 * len(NAMES), lam)
        return slice(lam, lam + self.num_fingers * self.joints)  # q

    @property
    def width(self) -> int:
        return 3 * len(NAMES) + self.num_fingers * (self.edges + self.joints)


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

    def __init__(
        self,
        scene,
        fingers,
        spec: SegmentSpec,
        mu: float,
        intervals: int,
        dt: float,
        links: bool = False,
        apart: np.ndarray | None = None,
    ):
        self.scene, self.fingers, self.spec = scene, fingers, spec
        self.hand = stacked(fingers)  # every finger at once
        self.links = links  # with the link rows (each capsule's axis at least its radius off the box)
        F, n = scene.num_fingers, len(scene.fingers[0].q_lower)
        self.clearance_row = 9 + 3 * F + n * F
        # the finger-finger rows of the part pairs `apart` (R, 4; space_fingers.near_parts), after the link rows
        parts = FingerParts.of(self.hand, scene.tip_radius)
        self.apart = SpaceFingerRows(parts, np.zeros((0, 4), dtype=int) if apart is None else np.asarray(apart))
        self.apart_row = self.clearance_row + 1 + (F * self.hand.link_joint.shape[-1] if links else 0)
        # m, each row's floor on the free knots: CLEARANCE, or less where a node (a fixed end knot, kept apart by
        # the search's own test on the exact shapes) already has it closer
        ends = [self.hand.chain(q[None]) for q in (spec.q_a, spec.q_b)]
        self.apart_floor = np.min(
            [np.full(self.apart.num_rows, CLEARANCE)]
            + [self.apart.values(tip, link_ends)[0] for _, _, tip, _, link_ends in ends],
            axis=0,
        )
        self.layout = Layout(F, n, PYRAMID_EDGES)
        self.K, self.h = intervals + 1, dt
        s, self.rate = time_law(intervals)
        self.axis_angle = so3_log(spec.R_b @ spec.R_a.T)  # W: the nominal turns about this at a fixed axis
        self.N = exp(s[:, None] * self.axis_angle) @ spec.R_a  # (K, 3, 3) nominal orientations
        self.w_nominal = self.rate[:, None] * self.axis_angle / dt  # rad/s: the rule holds at phi = 0
        # contacts per knot (in B): node a's, the switching finger's new one at the last knot
        self.p_BC = np.repeat(spec.p_BC_a[None], self.K, axis=0)
        self.n_B = np.repeat(spec.n_B_a[None], self.K, axis=0)
        if spec.switching is not None:
            self.p_BC[-1, spec.switching], self.n_B[-1, spec.switching] = (
                spec.p_BC_b[spec.switching],
                spec.n_B_b[spec.switching],
            )
        # Each knot's pyramids as the search builds them in W (statics.pyramid_edges of the normal in W) at the
        # knot's nominal orientation, in B: at the end knots exactly the pyramids the search held the nodes with.
        # The pyramid's turn about its normal follows the normal's direction in W, and an 8-edge pyramid turned
        # otherwise missed a node's hold within the motors (seed-0 goal 28: 0.402 N m where the search's held
        # it with 0.388 N m, and IPOPT failed in restoration).
        n_W = np.einsum("kij,kfj->kfi", self.N, self.n_B)
        edges_W = pyramid_edges(n_W.reshape(-1, 3), mu, PYRAMID_EDGES).reshape(self.K, F, PYRAMID_EDGES, 3)
        self.edges_B = np.einsum("kji,kfej->kfei", self.N, edges_W)
        self.pinned = np.ones((self.K, F), dtype=bool)
        self.clearance = np.zeros(self.K)
        if spec.switching is not None:
            self.pinned[1:-1, spec.switching] = False
            # on the lifted knots only: at the last, where sin(pi) is 1e-16 and not 0, the gap row would be
            # active where the pin already holds the fingertip, a redundant pair whose multipliers blow up
            lifted = ~self.pinned[:, spec.switching]
            self.clearance = np.where(lifted, SWITCH_CLEARANCE * np.sin(np.pi * np.arange(self.K) / intervals), 0.0)
        # 1/m: the squared gap's row divided by twice the largest gap, so that its gradient is about one, as the
        # pins' (20 segments of three seed-0 goals: 887 IPOPT iterations in all, 1046 unscaled)
        self.clearance_scale = 1.0 / (2 * (scene.tip_radius + SWITCH_CLEARANCE))
        self.set_object(scene, mu)

    def set_object(self, scene, mu: float) -> None:
        """The cube's, the fingertips' and the motors' constants the rows read, and the friction `mu`."""
        self.inertia = scene.object.inertia
        self.half = scene.object.half
        # kg m^2: L is in units of the cube's largest principal inertia (rad/s), its row's gradients near one
        self.momentum_unit = float(np.max(np.diag(self.inertia)))
        self.r, self.g = scene.tip_radius, scene.gravity
        self.tau_max = scene.tau_max
        self.mu = mu

    # -- values ------------------------------------------------------------------------------------
    def split(self, Z):
        lay = self.layout
        parts = {name: Z[:, lay.slice(name)] for name in (*NAMES, "lam", "q")}
        parts["lam"] = parts["lam"].reshape(self.K, lay.num_fingers, lay.edges)
        parts["q"] = parts["q"].reshape(self.K, lay.num_fingers, lay.joints)
        return parts

    def rotations(self, phi):
        return self.N @ exp(phi)

    def forces_B(self, lam):
        """(K, F, 3) each finger's force on the object in B."""
        return np.einsum("kfe,kfec->kfc", lam, self.edges_B)

    def _knot(self, Z, derivatives: bool):
        """The knots' variables, rotations, forces and the fingers' kinematics (with their derivatives)."""
        x = self.split(Z)
        R = self.rotations(x["phi"])
        f_B = self.forces_B(x["lam"])
        f_W = np.einsum("kij,kfj->kfi", R, f_B)
        n_W = np.einsum("kij,kfj->kfi", R, self.n_B)
        if derivatives:
            kin = self.hand.derivatives(x["q"], f_W, -self.r * n_W, self.g)
        else:
            kin = self.hand.torques(x["q"], f_W, -self.r * n_W, self.g)
        return x, R, f_B, f_W, n_W, kin

    def knot_values(self, Z):
        """(rows (K, 9 + 3F + nF + 1): F, T, L balance, fingertip pins (3F), joint torques (nF), clearance (1)),
        and the joint torques (K, F, n), the fingertip centres (K, F, 3)."""
        x, R, f_B, f_W, n_W, (tips, taus) = self._knot(Z, False)
        return self._rows(x, R, f_B, f_W, tips, taus), taus, tips

    def _rows(self, x, R, f_B, f_W, tips, taus):
        force = x["F"] - f_W.sum(1)
        moment = x["T"] - np.einsum("kij,kj->ki", R, np.cross(self.p_BC, f_B).sum(1))
        momentum = x["L"] - np.einsum("kij,jl,kml,km->ki", R, self.inertia, R, x["w"]) / self.momentum_unit
        targets = x["p"][:, None, :] + np.einsum("kij,kfj->kfi", R, self.p_BC + self.r * self.n_B)
        pins = (tips - targets).reshape(self.K, -1)
        clearance = np.zeros(self.K)
        if self.spec.switching is not None:
            out = self._outside(R, tips[:, self.spec.switching] - x["p"])[1]
            clearance = np.sum(out * out, -1) * self.clearance_scale
        rows = [force, moment, momentum, pins, taus.reshape(self.K, -1), clearance[:, None]]
        if self.links:
            rows.append(self._link_rows(x, R)[0].reshape(self.K, -1))
        _, _, tip, _, link_ends = self.hand.chain(x["q"])
        rows.append(self.apart.values(tip, link_ends))
        return np.concatenate(rows, axis=1)

    def _link_rows(self, x, R, J_r=None):
        """The signed distance from the box of each link capsule's axis (K, F, L), at its nearest point (the
        golden-section search of geometry.segment_box_nearest), and with J_r its derivatives in q_i (K, F, L, n),
        p (K, F, L, 3) and phi (K, F, L, 3): at a minimum over the axis, those of the distance at that point."""
        points, axes, _, _, ends = self.hand.chain(x["q"])
        e_B = np.einsum("kji,kflej->kflei", R, ends - x["p"][:, None, None, None, :])
        t = segment_box_nearest(self.half, e_B[..., 0, :], e_B[..., 1, :], LINK_SEARCH_ITERATIONS)[..., None]
        x_B = (1 - t) * e_B[..., 0, :] + t * e_B[..., 1, :]
        value = box_signed_distances(self.half, x_B)
        if J_r is None:
            return (value,)
        g = box_signed_distance_gradient(self.half, x_B)  # d value / d x_B
        x_W = (1 - t) * ends[..., 0, :] + t * ends[..., 1, :]  # (K, F, L, 3)
        lever = cross(axes[:, :, None], x_W[:, :, :, None, :] - points[:, :, None])  # (K, F, L, n, 3)
        n = self.layout.joints
        turned = np.arange(n)[None, :] <= self.hand.link_joint[0][:, None]  # (L, n): joint k turns capsule l
        gR = np.einsum("kfli,kji->kflj", g, R)  # d value / d x_W
        dq = np.einsum("kflj,kflnj->kfln", gR, lever) * turned
        dphi = np.einsum("kfli,kflij->kflj", g, skew(x_B) @ J_r[:, None, None])
        return value, dq, -gR, dphi

    def contact_points_B(self, tips_B):
        """(K, F, 3) where each force acts on the box, in B: a pinned finger's contact, else the box point nearest
        its fingertip centre tips_B (K, F, 3)."""
        return np.where(self.pinned[..., None], self.p_BC, np.clip(tips_B, -self.half, self.half))

    def _outside(self, R, tip_rel):
        """(p_B (K, 3) the switching fingertip's centre in B, its excess over the box's half sizes, >= 0)."""
        p_B = np.einsum("kji,kj->ki", R, tip_rel)
        d = np.abs(p_B) - self.half
        return p_B, np.where(d > 0, d, 0.0)

    def pair_values(self, Z):
        """(K - 1, 3): vee(Q - Q^T) / 2, Q = exp(-[h w_mid]x) R[k+1] R[k]^T."""
        x = self.split(Z)
        R = self.rotations(x["phi"])
        w_mid = 0.5 * (x["w"][1:] + x["w"][:-1])
        return vee_skew(exp(-self.h * w_mid) @ R[1:] @ np.swapaxes(R[:-1], -1, -2))

    def knot_bounds(self, free_last: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) (K, rows) of the knot rows; the link and finger-finger rows bound on the free knots
        only (the inner ones, and the last where `free_last`: a node inside the joint program's horizon)."""
        F = self.layout.num_fingers
        n = self.layout.joints
        L = self.hand.link_joint.shape[-1]
        lo, hi = [], []
        for k in range(self.K):
            pin = np.where(np.repeat(self.pinned[k], 3), 0.0, np.inf)
            gap = (self.r + self.clearance[k]) ** 2 * self.clearance_scale if self.clearance[k] > 0 else -np.inf
            lo.append(np.concatenate([np.zeros(9), -pin, -self.tau_max.reshape(F * n), [gap]]))
            hi.append(np.concatenate([np.zeros(9), pin, self.tau_max.reshape(F * n), [np.inf]]))
            free = 0 < k < self.K - 1 or (free_last and k == self.K - 1)
            if self.links:  # on the free knots: the nodes' links the search kept 2 mm off
                lo[-1] = np.concatenate([lo[-1], self.hand.link_radius.ravel() if free else np.full(F * L, -np.inf)])
                hi[-1] = np.concatenate([hi[-1], np.full(F * L, np.inf)])
            lo[-1] = np.concatenate([lo[-1], self.apart_floor if free else np.full(self.apart.num_rows, -np.inf)])
            hi[-1] = np.concatenate([hi[-1], np.full(self.apart.num_rows, np.inf)])
        return np.array(lo), np.array(hi)

    # -- the Jacobian ------------------------------------------------------------------------------
    def knot_mask(self) -> np.ndarray:
        """(rows, width) bool: the variables of its own knot each knot row depends on."""
        lay = self.layout
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        mask = np.zeros((self.apart_row + self.apart.num_rows, lay.width), dtype=bool)
        mask[:, lay.slice("phi")] = True
        lam, q = lay.slice("lam").start, lay.slice("q").start
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            mask[row : row + 3, lay.slice(name)] = True
        mask[0:6, lay.slice("lam")] = True
        mask[6:9, lay.slice("w")] = True
        for i in range(F):
            joints = slice(q + n * i, q + n * (i + 1))
            mask[9 + 3 * i : 12 + 3 * i, lay.slice("p")] = True
            mask[9 + 3 * i : 12 + 3 * i, joints] = True
            taus = slice(9 + 3 * F + n * i, 9 + 3 * F + n * (i + 1))
            mask[taus, joints] = True
            mask[taus, lam + m * i : lam + m * (i + 1)] = True
        c = self.clearance_row
        if self.spec.switching is None:
            mask[c] = False  # no clearance row: zero
        else:
            s = self.spec.switching
            mask[c, lay.slice("p")] = True
            mask[c, q + n * s : q + n * (s + 1)] = True
        if self.links:
            L = self.hand.link_joint.shape[-1]
            for i in range(F):  # finger i's capsules
                rows = slice(c + 1 + L * i, c + 1 + L * (i + 1))
                mask[rows, lay.slice("phi")] = mask[rows, lay.slice("p")] = True
                mask[rows, q + n * i : q + n * (i + 1)] = True
        for r, (a, _, b, _) in enumerate(self.apart.pairs.tolist()):  # both fingers' joints
            mask[self.apart_row + r, q + n * a : q + n * (a + 1)] = True
            mask[self.apart_row + r, q + n * b : q + n * (b + 1)] = True
        return mask

    def pair_mask(self) -> np.ndarray:
        """(3, width) bool: the variables of either knot a pair row depends on."""
        mask = np.zeros((3, self.layout.width), dtype=bool)
        mask[:, self.layout.slice("phi")] = mask[:, self.layout.slice("w")] = True
        return mask

    def jacobians(self, Z):
        """(knot rows (K, Rk), their Jacobian (K, Rk, width); pair rows (K-1, 3), Jacobians on knot k and
        k+1 (K-1, 3, width) each), analytic: R = N exp([phi]x) perturbs as R exp([J_r dphi]x), so a vector
        u fixed in B turns as d(R u) = -R [u]x J_r dphi (turned)."""
        lay = self.layout
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        x, R, f_B, f_W, _, (tips, taus, J_tip, J_C, dtau_dq, axes) = self._knot(Z, True)
        rows = self._rows(x, R, f_B, f_W, tips, taus)
        J_r = right_jacobian(x["phi"])
        phi, eye = lay.slice("phi"), np.eye(3)
        Jk = np.zeros(rows.shape + (lay.width,))
        Jk[:, 0:3, phi] = -turned(R, J_r, f_B.sum(1))
        Jk[:, 3:6, phi] = -turned(R, J_r, np.cross(self.p_BC, f_B).sum(1))
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            Jk[:, row : row + 3, lay.slice(name)] = eye
        # momentum L - R I R^T w: with a = R^T w, d(R I a) = R ([I a]x - I [a]x) J_r dphi + R I R^T dw
        a = np.einsum("kji,kj->ki", R, x["w"])
        Jk[:, 6:9, phi] = R @ (skew(a @ self.inertia) - self.inertia @ skew(a)) @ J_r / self.momentum_unit
        Jk[:, 6:9, lay.slice("w")] = -R @ self.inertia @ np.swapaxes(R, -1, -2) / self.momentum_unit
        edges_W = np.einsum("kij,kfej->kfei", R, self.edges_B)  # (K, F, m, 3)
        moments_W = np.einsum("kij,kfej->kfei", R, np.cross(self.p_BC[:, :, None, :], self.edges_B))
        lam0, q0 = lay.slice("lam").start, lay.slice("q").start
        pin_phi = -turned(R, J_r, self.p_BC + self.r * self.n_B)  # (K, F, 3, 3)
        # tau_j = (a_j x (tip - r n_W - p_j)) . f_W: f_W and n_W turn with phi, d tau_j = J_C,j . df_W
        # - r (f_W x a_j) . dn_W
        tau_phi = J_C @ turned(R, J_r, f_B) - self.r * cross(f_W[:, :, None, :], axes) @ turned(R, J_r, self.n_B)
        for i in range(F):
            lam_i, q_i = slice(lam0 + m * i, lam0 + m * (i + 1)), slice(q0 + n * i, q0 + n * (i + 1))
            pins, tau_rows = slice(9 + 3 * i, 12 + 3 * i), slice(9 + 3 * F + n * i, 9 + 3 * F + n * (i + 1))
            Jk[:, 0:3, lam_i] = -np.swapaxes(edges_W[:, i], -1, -2)
            Jk[:, 3:6, lam_i] = -np.swapaxes(moments_W[:, i], -1, -2)
            Jk[:, pins, phi] = pin_phi[:, i]
            Jk[:, pins, lay.slice("p")] = -eye
            Jk[:, pins, q_i] = J_tip[:, i]
            Jk[:, tau_rows, lam_i] = np.einsum("kjc,kec->kje", J_C[:, i], edges_W[:, i])
            Jk[:, tau_rows, q_i] = dtau_dq[:, i]
            Jk[:, tau_rows, phi] = tau_phi[:, i]
        if self.spec.switching is not None:
            self._clearance_columns(Jk, x, R, J_r, tips, J_tip)
        if self.links:
            self._link_columns(Jk, x, R, J_r)
        self._apart_columns(Jk, x)
        return rows, Jk, self.pair_values(Z), *self._pair_jacobians(x, R, J_r)

    def _apart_columns(self, Jk, x) -> None:
        """The finger-finger rows' columns: each row's two fingers' joints (space_fingers.SpaceFingerRows)."""
        if not self.apart.num_rows:
            return
        n = self.layout.joints
        points, axes, tip, _, link_ends = self.hand.chain(x["q"])
        _, d_a, d_b = self.apart.jacobians(points, axes, tip, link_ends)
        rows = self.apart_row + np.arange(self.apart.num_rows)[:, None]
        q0, a, b = self.layout.slice("q").start, self.apart.pairs[:, 0], self.apart.pairs[:, 2]
        Jk[:, rows, q0 + n * a[:, None] + np.arange(n)] = d_a
        Jk[:, rows, q0 + n * b[:, None] + np.arange(n)] = d_b

    def _clearance_columns(self, Jk, x, R, J_r, tips, J_tip) -> None:
        """The clearance row sum(out^2), out = max(|p_B| - half, 0), p_B = R^T (tip - p): d p_B = R^T (J_tip dq
        - dp) + [p_B]x J_r dphi."""
        lay, s, n = self.layout, self.spec.switching, self.layout.joints
        p_B, out = self._outside(R, tips[:, s] - x["p"])
        g = 2 * self.clearance_scale * out * np.where(p_B < 0, -1.0, 1.0)  # d row / d p_B (K, 3)
        gR = np.einsum("ki,kji->kj", g, R)  # g R^T (K, 3): d row / d tip
        q, c = lay.slice("q").start + n * s, self.clearance_row
        Jk[:, c, q : q + n] = np.einsum("kj,kjc->kc", gR, J_tip[:, s])
        Jk[:, c, lay.slice("p")] = -gR
        Jk[:, c, lay.slice("phi")] = np.einsum("ki,kij->kj", g, skew(p_B) @ J_r)

    def _link_columns(self, Jk, x, R, J_r) -> None:
        lay = self.layout
        F, n, L = lay.num_fingers, lay.joints, self.hand.link_joint.shape[-1]
        _, dq, dp, dphi = self._link_rows(x, R, J_r)
        first, q0 = self.clearance_row + 1, lay.slice("q").start
        for i in range(F):
            rows = slice(first + L * i, first + L * (i + 1))
            Jk[:, rows, q0 + n * i : q0 + n * (i + 1)] = dq[:, i]
            Jk[:, rows, lay.slice("p")] = dp[:, i]
            Jk[:, rows, lay.slice("phi")] = dphi[:, i]

    def _pair_jacobians(self, x, R, J_r):
        """(d pair / d knot k, d pair / d knot k + 1), each (K-1, 3, width). With Q = E R[k+1] R[k]^T, E =
        exp(-[h w_mid]x): dphi[k+1] gives dQ = [E R[k+1] J_r dphi]x Q, dphi[k] dQ = -Q [R[k] J_r dphi]x, dw at
        either knot dQ = [E J_r(-h w_mid) (-h / 2) dw]x Q; vee of the skew part is linear in the vector."""
        lay = self.layout
        w_mid = 0.5 * (x["w"][1:] + x["w"][:-1])
        E = exp(-self.h * w_mid)
        Q = E @ R[1:] @ np.swapaxes(R[:-1], -1, -2)
        left = np.stack([vee_skew(B @ Q) for B in BASIS_SKEW], -1)  # (K-1, 3, 3): u -> vee skew([u]x Q)
        right = np.stack([vee_skew(Q @ B) for B in BASIS_SKEW], -1)  # u -> vee skew(Q [u]x)
        dw = left @ E @ right_jacobian(-self.h * w_mid) * (-0.5 * self.h)
        Jl = np.zeros((self.K - 1, 3, lay.width))
        Jr = np.zeros_like(Jl)
        Jl[:, :, lay.slice("phi")] = -right @ R[:-1] @ J_r[:-1]
        Jr[:, :, lay.slice("phi")] = left @ E @ R[1:] @ J_r[1:]
        Jl[:, :, lay.slice("w")] = Jr[:, :, lay.slice("w")] = dw
        return Jl, Jr


class SegmentConstraint:
    """Drake's evaluator for a segment's nonlinear rows (knot rows, then pair rows) over all its knots'
    variables, knot after knot: float input gives the values, AutoDiffXd input values and gradient, the
    analytic Jacobian scattered into the binding's sparsity pattern (SpaceSegmentRows.knot_mask and pair_mask
    per knot). Drake's solvers pass identity input gradients, which skip the chain rule's product."""

    def __init__(self, rows: SpaceSegmentRows):
        self.rows = rows
        K, W = rows.K, rows.layout.width
        knot = rows.knot_mask()
        self.num_knot_rows = knot.shape[0]
        Rk = self.num_knot_rows
        self.shape = (K * Rk + 3 * (K - 1), K * W)
        # (binding row, binding column, flat index into the knot or pair Jacobians) of every entry
        k, r, c = np.nonzero(np.broadcast_to(knot, (K,) + knot.shape))
        pk, pr, pc = np.nonzero(np.broadcast_to(rows.pair_mask(), (K - 1, 3, W)))
        self.knot_entries = (k * Rk + r, k * W + c, (k * Rk + r) * W + c)
        base = K * Rk
        self.pair_entries = (base + 3 * pk + pr, pk * W + pc, (pk * 3 + pr) * W + pc)

    def values(self, Z) -> np.ndarray:
        return np.concatenate([self.rows.knot_values(Z)[0].ravel(), self.rows.pair_values(Z).ravel()])

    def jacobian(self, Z) -> tuple[np.ndarray, np.ndarray]:
        rows, Jk, pair, Jl, Jr = self.rows.jacobians(Z)
        J = np.zeros(self.shape)
        r, c, source = self.knot_entries
        J[r, c] = Jk.reshape(-1)[source]
        r, c, source = self.pair_entries
        J[r, c] = Jl.reshape(-1)[source]
        J[r, c + self.rows.layout.width] = Jr.reshape(-1)[source]
        return np.concatenate([rows.ravel(), pair.ravel()]), J

    def sparsity(self) -> list[tuple[int, int]]:
        r, c, _ = self.knot_entries
        pr, pc, _ = self.pair_entries
        W = self.rows.layout.width
        rows = np.concatenate([r, pr, pr])
        cols = np.concatenate([c, pc, pc + W])
        return list(zip(rows.tolist(), cols.tolist()))

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
    cpu_time_s: float  # s of this process's CPU time, build and solve (wall time counts other processes' too)
    link_rows: bool  # solved again with the link rows (the first solve had a link over 1 mm inside the box)
    pid: int  # the process that solved it
    t: np.ndarray  # (K,) s from the segment's start
    x: np.ndarray  # (K, 7)
    v: np.ndarray  # (K, 6)
    q: np.ndarray  # (K, F n)
    tau: np.ndarray  # (K, F n)
    f_W: np.ndarray  # (K, F, 3)
    p_W_C: np.ndarray  # (K, F, 3)
    p_W_tip: np.ndarray  # (K, F, 3)


def guess(rows: SpaceSegmentRows) -> np.ndarray:
    """Knot values: the nominal (phi = 0) at rest in position, the holding fingers' joints by Newton's method
    onto their contacts from the nodes' interpolation, the switching finger's along a path lifted off the box,
    and the forces of the holding LP at each knot (quasi-static)."""
    spec, lay, K = rows.spec, rows.layout, rows.K
    Z = np.zeros((K, lay.width))
    Z[:, lay.slice("p")] = spec.p
    Z[:, lay.slice("w")] = rows.w_nominal
    Z[:, lay.slice("L")] = (
        np.einsum("kij,jl,kml,km->ki", rows.N, rows.inertia, rows.N, rows.w_nominal) / rows.momentum_unit
    )
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


@dataclass(frozen=True)
class SpaceSegmentProgram:
    """One segment's program, its initial guess set (guess)."""

    prog: MathematicalProgram
    z: np.ndarray  # (K, width) the knots' variables
    rows: SpaceSegmentRows
    binding: object  # the nonlinear rows (SegmentConstraint) over z, knot after knot
    build_time_s: float


def add_rule(prog, var: dict, rows, m: float) -> None:
    """The rule's linear rows between knots: p[k+1] - p[k] - h/2 (v[k] + v[k+1]) = 0, m (v[k+1] - v[k]) - h/2 (F[k]
    + F[k+1]) = h m g, L likewise (in units of rows.momentum_unit)."""
    h, eye = rows.h, np.eye(3)
    for k in range(rows.K - 1):
        pk = np.concatenate([var["p"][k], var["p"][k + 1], var["v"][k], var["v"][k + 1]])
        prog.AddLinearEqualityConstraint(np.hstack([-eye, eye, -h / 2 * eye, -h / 2 * eye]), np.zeros(3), pk)
        vk = np.concatenate([var["v"][k], var["v"][k + 1], var["F"][k], var["F"][k + 1]])
        g = np.array([0.0, 0.0, -h * m * rows.g])
        prog.AddLinearEqualityConstraint(np.hstack([-m * eye, m * eye, -h / 2 * eye, -h / 2 * eye]), g, vk)
        lk = np.concatenate([var["L"][k], var["L"][k + 1], var["T"][k], var["T"][k + 1]])
        u = rows.momentum_unit
        prog.AddLinearEqualityConstraint(np.hstack([-u * eye, u * eye, -h / 2 * eye, -h / 2 * eye]), np.zeros(3), lk)


def add_costs(prog, var: dict, lay: Layout, K: int) -> None:
    """The small quadratic costs: the forces' edge magnitudes, the corrections phi and the joints' steps."""
    nq = lay.num_fingers * lay.joints
    for k in range(K):
        prog.AddQuadraticCost(
            2 * WEIGHT_FORCE * np.eye(lay.num_fingers * lay.edges),
            np.zeros(lay.num_fingers * lay.edges),
            var["lam"][k],
            is_convex=True,
        )
        prog.AddQuadraticCost(2 * WEIGHT_PHI * np.eye(3), np.zeros(3), var["phi"][k], is_convex=True)
    for k in range(K - 1):
        Q = np.block([[np.eye(nq), -np.eye(nq)], [-np.eye(nq), np.eye(nq)]]) * 2 * WEIGHT_JOINT_STEP
        prog.AddQuadraticCost(Q, np.zeros(2 * nq), np.concatenate([var["q"][k], var["q"][k + 1]]), is_convex=True)


def build_space_segment(
    scene, fingers, spec: SegmentSpec, mu: float, links: bool = False, start: np.ndarray | None = None
) -> SpaceSegmentProgram:
    """One segment's program (see the module's doc), with the link rows or not, from `start` (K, width), else
    from its guess."""
    t0 = time.perf_counter()
    rows = SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links)
    start = guess(rows) if start is None else start
    rows = SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links, near_apart(rows, start))
    lay, K = rows.layout, rows.K
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, lay.width, "z")
    var = {name: z[:, lay.slice(name)] for name in (*NAMES, "lam", "q")}
    m = scene.object.mass
    add_rule(prog, var, rows, m)
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
    constraint = SegmentConstraint(rows)
    lo, hi = rows.knot_bounds()
    binding = prog.AddConstraint(
        constraint,
        np.concatenate([lo.ravel(), np.zeros(3 * (K - 1))]),
        np.concatenate([hi.ravel(), np.zeros(3 * (K - 1))]),
        z.ravel(),
        description="space segment",
    )
    binding.evaluator().SetGradientSparsityPattern(constraint.sparsity())
    add_costs(prog, var, lay, K)
    # by name: Drake orders a matrix's variables column-major
    prog.SetInitialGuess(z, start)
    return SpaceSegmentProgram(prog, z, rows, binding, time.perf_counter() - t0)


def near_apart(rows: SpaceSegmentRows, Z) -> np.ndarray:
    """(R, 4): the pairs of two fingers' parts that come within space_fingers.NEAR_MARGIN of each other over
    the knots Z (K, width): the program's start, its guess or a solution."""
    _, _, tip, _, link_ends = rows.hand.chain(rows.split(Z)["q"])
    return near_parts(rows.apart.parts, rows.apart.parts.ends(tip, link_ends))


def finger_overlap(rows: SpaceSegmentRows, Z) -> float:
    """m, how deep the deepest two parts of two fingers reach into each other over the knots Z (0: none do), as
    the physics check measures it, every pair of parts (not only the program's rows)."""
    _, _, tip, _, link_ends = rows.hand.chain(rows.split(Z)["q"])
    ends = rows.apart.parts.ends(tip, link_ends)
    return max(-least_part_distance(rows.apart.parts, ends), 0.0)


def solve_space_segment(scene, fingers, spec: SegmentSpec, mu: float, config: CitoConfig) -> SpaceSegmentResult:
    """One segment's program, built and solved by IPOPT (cito.solve's options) from the guess; `scene` a
    SpaceScene or its SpaceHandModel (cito.space_hand), `fingers` the chains of space_hand.space_fingers."""
    program, result, Z, times = solve_with_link_retry(
        lambda links, Z: build_space_segment(scene, fingers, spec, mu, links, Z),
        lambda program, Z: max(link_depth(program.rows, Z), finger_overlap(program.rows, Z)),
        config,
    )
    return segment_arrays(program.rows, Z, result, times)


def solve_with_link_retry(build, depth, config: CitoConfig, Z=None):
    """IPOPT (cito.solve's options) on build(links=False, Z), then once more on build(True, its solution) when
    depth(program, solution) (m, the deepest link in the box or, in space's segments, two fingers' deepest
    overlap, whose rows the rebuild picks again near that solution) exceeds LINK_PENETRATION_TOL; (the last program,
    its result, its solution, (build s, solve s, CPU s) of both). Segments, the joint program and CITO alike."""
    cpu = time.process_time()
    build_s = solve_s = 0.0
    for links in (False, True):
        program = build(links, Z)
        t0 = time.perf_counter()
        result = IpoptSolver().Solve(program.prog, None, ipopt_options(config))
        build_s, solve_s = build_s + program.build_time_s, solve_s + time.perf_counter() - t0
        Z = result.GetSolution(program.z)
        if not result.is_success() or depth(program, Z) <= LINK_PENETRATION_TOL:
            break
    return program, result, Z, (build_s, solve_s, time.process_time() - cpu)


def link_depth(rows: SpaceSegmentRows, Z) -> float:
    """m, how deep the deepest link capsule reaches into the box over the knots Z (0: none does), as the physics
    check measures it (geometry.segment_box_distances)."""
    x = rows.split(Z)
    R = rows.rotations(x["phi"])
    ends = rows.hand.chain(x["q"])[4]
    e_B = np.einsum("kji,kflej->kflei", R, ends - x["p"][:, None, None, None, :])
    depth = rows.hand.link_radius - segment_box_distances(rows.half, e_B[..., 0, :], e_B[..., 1, :])
    return float(max(depth.max(), 0.0))


def segment_arrays(rows: SpaceSegmentRows, Z, result, times: tuple[float, float, float]) -> SpaceSegmentResult:
    """The arrays of a solved segment; `times` (build, solve, CPU) in s."""
    x = rows.split(Z)
    R = rows.rotations(x["phi"])
    _, taus, tips = rows.knot_values(Z)
    f_W = np.einsum("kij,kfj->kfi", R, rows.forces_B(x["lam"]))
    p = x["p"]
    tips_B = np.einsum("kji,kfj->kfi", R, tips - p[:, None, :])
    p_BC = rows.contact_points_B(tips_B)
    details = result.get_solver_details()
    return SpaceSegmentResult(
        success=bool(result.is_success()),
        status=details.ConvertStatusToString(),
        iterations=-1,
        build_time_s=times[0],
        solve_time_s=times[1],
        cpu_time_s=times[2],
        link_rows=rows.links,
        pid=os.getpid(),
        t=rows.h * np.arange(rows.K),
        x=np.hstack([matrix_quaternions(R), p]),
        v=np.hstack([x["w"], x["v"]]),
        q=x["q"].reshape(rows.K, -1),
        tau=taus.reshape(rows.K, -1),
        f_W=f_W,
        p_W_C=p[:, None, :] + np.einsum("kij,kfj->kfi", R, p_BC),
        p_W_tip=tips,
    )
