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
(p + R (p_BC + r n_B), fixed in B); the joint torques of a quasi-static hand (the fingers' own weight and
J_C^T f at the contact point; the fingers' inertia left out, 2-3 orders below the motors at these speeds)
within the motors; the switching finger's centre at least r + clearance sin(pi k / N) off the box while lifted.
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
(SpaceSegmentRows.jacobians, knot_mask, pair_mask).
"""

from __future__ import annotations

import copy
import os
import time
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import IpoptSolver, MathematicalProgram
from scipy.optimize import nnls

from trajectotree.cito.solve import ipopt_options
from trajectotree.cito.space_fingers import (
    CLEARANCE,
    FingerParts,
    SpaceFingerRows,
    least_part_distance,
    near_parts,
)
from trajectotree.config import CitoConfig
from trajectotree.geometry import (
    BOX_FACE_NAMES,
    BOX_FACE_NORMALS,
    box_face_normals,
    box_signed_distances,
    matrix_quaternions,
    quaternion_matrices,
    segment_box_distances,
    segment_box_nearest,
    so3_log,
)
from trajectotree.results import LINK_PENETRATION_TOL
from trajectotree.scene.spatial import SpaceObject
from trajectotree.scene.statics import pyramid_edges
from trajectotree.search.stance import SpatialHoldingLp, spatial_torque_rows
from trajectotree.search.tree import space_object_path

PHI_BOUND = 0.3  # rad, each component of the correction to the nominal (the nominal segment turns <= 20 deg)
SPACE_INTERVALS = 10  # knots per segment - 1
SPACE_DT = 0.1  # s between knots: a segment lasts 1 s
PYRAMID_EDGES = 8  # as the search's stances, turned as theirs (SpaceSegmentRows.edges_B)
SWITCH_CLEARANCE = 0.01  # m, the lifted fingertip's least gap at mid-segment (sin profile, as in the plane)
WEIGHT_FORCE = 0.01  # per N^2 of edge magnitude
WEIGHT_JOINT_STEP = 1.0  # per rad^2 of joint motion between knots
WEIGHT_PHI = 1.0  # per rad^2 of correction
LINK_SEARCH_ITERATIONS = 30  # golden-section steps along a capsule's axis: 0.618^30 = 5e-7 of its length
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


# -- kinematics -------------------------------------------------------------------------------------
def _skew(v):
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
         np.stack([-v[..., 1], v[..., 0], z], -1)],
        axis=-2,
    )  # fmt: skip


def _exp(phi):
    """exp([phi]x) (..., 3, 3) for phi (..., 3) (Rodrigues, series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = theta2 < 1e-10
    t2 = np.where(small, 1.0, theta2)
    theta = np.sqrt(t2)
    a = np.where(small, 1.0 - theta2 / 6 + theta2**2 / 120, np.sin(theta) / theta)
    b = np.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - np.cos(theta)) / t2)
    K = _skew(phi)
    return np.eye(3) + a * K + b * (K @ K)


def _right_jacobian(phi):
    """J_r(phi) (..., 3, 3): exp([phi + d]x) = exp([phi]x) exp([J_r d]x) to first order in d (series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = theta2 < 1e-10
    t2 = np.where(small, 1.0, theta2)
    theta = np.sqrt(t2)
    a = np.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - np.cos(theta)) / t2)
    b = np.where(small, 1.0 / 6 - theta2 / 120 + theta2**2 / 5040, (theta - np.sin(theta)) / (t2 * theta))
    K = _skew(phi)
    return np.eye(3) - a * K + b * (K @ K)


def _turned(R, J_r, u):
    """d(R u)/dphi (K, ..., 3, 3) for u (K, ..., 3) fixed in B, R = N exp([phi]x) (K, 3, 3), J_r at phi:
    -R [u]x J_r."""
    shape = (len(R),) + (1,) * (u.ndim - 2) + (3, 3)
    return -R.reshape(shape) @ _skew(u) @ J_r.reshape(shape)


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


def _vee_skew(M):
    """vee((M - M^T) / 2) (..., 3) of M (..., 3, 3)."""
    return 0.5 * np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1)


_BASIS_SKEW = _skew(np.eye(3))  # [e_i]x, i = 0..2


@dataclass(frozen=True)
class _Finger:
    """A finger's chain at zero angles (scene.kinematics.SerialFinger) and its links' masses and centres of
    mass (link j beyond joint j), for forward kinematics and gravity torques; the arrays may carry a leading
    axis of fingers (_stacked), all with the same number n of joints."""

    p_W_joint: np.ndarray  # ([F,] n, 3)
    a_W: np.ndarray  # ([F,] n, 3)
    p_W_tip0: np.ndarray  # ([F,] 3)
    p_W_com0: np.ndarray  # ([F,] n, 3)
    mass: np.ndarray  # ([F,] n) kg
    p_W_link0: np.ndarray  # ([F,] L, 2, 3) m, the ends of the links' capsule axes
    link_joint: np.ndarray  # ([F,] L) the joint whose child body carries each capsule (the same in every finger)
    link_radius: np.ndarray  # ([F,] L) m

    def _owners(self) -> np.ndarray:
        """The last joint that turns each point of chain's rows: joint point j (j - 1), the tip (n - 1), centre
        of mass l (l), then each capsule's two ends (its joint)."""
        n = self.a_W.shape[-2]
        links = np.repeat(np.asarray(self.link_joint).reshape(-1, self.link_joint.shape[-1])[0], 2)
        return np.concatenate([np.arange(n) - 1, [n - 1], np.arange(n), links])

    def chain(self, q):
        """(points (..., n, 3), axes (..., n, 3), tip (..., 3), centres of mass (..., n, 3), capsule ends
        (..., L, 2, 3)) at q (..., n): joint j turns the points beyond it about its current axis."""
        n = self.a_W.shape[-2]
        shape = q.shape[:-1]
        L = self.link_joint.shape[-1]
        P = np.broadcast_to(
            np.concatenate(
                [
                    self.p_W_joint,
                    self.p_W_tip0[..., None, :],
                    self.p_W_com0,
                    self.p_W_link0.reshape(self.p_W_link0.shape[:-3] + (2 * L, 3)),
                ],
                axis=-2,
            ),
            shape + (2 * n + 1 + 2 * L, 3),
        ).astype(float)
        A = np.broadcast_to(self.a_W, shape + (n, 3)).astype(float)
        owners = self._owners()
        for j in range(n):
            c, a = P[..., j, :], A[..., j, :]
            moving = np.flatnonzero(owners >= j)
            P[..., moving, :] = c[..., None, :] + _rotate(a, q[..., j], P[..., moving, :] - c[..., None, :])
            A[..., j + 1 :, :] = _rotate(a, q[..., j], A[..., j + 1 :, :])
        ends = P[..., 2 * n + 1 :, :].reshape(shape + (L, 2, 3))
        return P[..., :n, :], A, P[..., n, :], P[..., n + 1 : 2 * n + 1, :], ends

    def torques(self, q, f_W, p_FC_W, gravity: float):
        """(tip (..., 3), tau (..., n)): the motors' torques that hold the finger still against its weight and
        push with f_W (..., 3) at the point p_FC_W (..., 3) from the tip centre (quasi-static)."""
        points, axes, tip, coms, _ = self.chain(q)
        return tip, self._push(axes, points, tip + p_FC_W, f_W) + self._weight(axes, points, coms, gravity)

    @staticmethod
    def _push(axes, points, lever, f_W):
        return np.sum(_cross(axes, lever[..., None, :] - points) * f_W[..., None, :], -1)

    def _weight(self, axes, points, coms, gravity: float):
        # joint j carries links j..n-1: tau_j = sum_l m_l g e_z . (a_j x (c_l - p_j))
        moment = _cross(axes[..., :, None, :], coms[..., None, :, :] - points[..., :, None, :])[..., 2]
        n = self.a_W.shape[-2]
        beyond = np.triu(np.ones((n, n)))  # [j, l]: link l is beyond joint j
        return gravity * np.sum(moment * beyond * self.mass[..., None, :], -1)

    def derivatives(self, q, f_W, p_FC_W, gravity: float):
        """(tip (..., 3), tau (..., n), J_tip (..., 3, n) the tip centre's Jacobian, J_C (..., n, 3) the lever
        rows a_j x (c - p_j) at the contact point c = tip + p_FC_W, dtau/dq (..., n, n), the axes (..., n, 3)).
        A joint k turns the axes and points beyond it: d a_j = a_k x a_j and d(x - p_j) = a_k x (x - p_j) for
        k < j; for k >= j only the tip and the links from k on move, d x = a_k x (x - p_k)."""
        points, axes, tip, coms, _ = self.chain(q)
        n = self.a_W.shape[-2]
        lever = tip + p_FC_W
        J_C = _cross(axes, lever[..., None, :] - points)
        tau = np.sum(J_C * f_W[..., None, :], -1) + self._weight(axes, points, coms, gravity)
        U = _cross(axes, tip[..., None, :] - points)  # (..., k, 3): d tip / d q_k
        a_j, a_k = axes[..., :, None, :], axes[..., None, :, :]  # (..., j, k, 3)
        before = np.tril(np.ones((n, n)), -1)[..., None]  # [j, k]: k < j
        to_tip = tip[..., None, :] - points  # (..., j, 3)
        inner = _cross(_cross(a_k, a_j), (lever[..., None, :] - points)[..., :, None, :]) + _cross(
            a_j, _cross(a_k, to_tip[..., :, None, :])
        )
        outer = _cross(a_j, U[..., None, :, :])
        dpush = np.sum(np.where(before, inner, outer) * f_W[..., None, None, :], -1)
        # the weight: [j, k, l]
        rel = coms[..., None, :, :] - points[..., :, None, :]  # (..., i, l, 3): c_l - p_i
        rel_j, rel_k = rel[..., :, None, :, :], rel[..., None, :, :, :]  # (..., j, k, l, 3)
        A_j, A_k = axes[..., :, None, None, :], axes[..., None, :, None, :]
        inner_g = _cross(_cross(A_k, A_j), rel_j) + _cross(A_j, _cross(A_k, rel_j))
        outer_g = _cross(A_j, _cross(A_k, rel_k))
        jj, kk, ll = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
        gz = np.where((kk < jj)[..., None], inner_g, outer_g)[..., 2]
        carried = (ll >= jj) & (ll >= kk)  # link l carried by joint j and turned by joint k
        dweight = gravity * np.sum(gz * carried * self.mass[..., None, None, :], -1)
        return tip, tau, np.swapaxes(U, -1, -2), J_C, dpush + dweight, axes


def _stacked(fingers) -> _Finger:
    """The fingers as one _Finger with a leading axis of fingers (the same number of joints each)."""
    return _Finger(*(np.stack([getattr(f, name) for f in fingers]) for name in _Finger.__dataclass_fields__))


def space_fingers(scene) -> tuple[_Finger, ...]:
    """Each finger's chain, its links' masses and centres of mass and its link capsules at zero angles, from the
    plant."""
    plant = scene.plant
    context = plant.CreateDefaultContext()
    start, zero = np.r_[1.0, 0, 0, 0, 0, 0, 0], np.zeros(scene.hand_q_indices.size)
    plant.SetPositions(context, scene.positions(start, zero))
    capsules = scene.link_capsules()
    ends = scene.link_ends_W(start[None], zero[None])[0]  # (F, L, 2, 3)
    out = []
    for i, (chain, entry) in enumerate(zip(scene.fingers, scene.hand_file.fingers)):
        bodies = [plant.GetJointByName(n, scene.hand).child_body() for n in entry.joints]
        coms = [b.EvalPoseInWorld(context) @ b.CalcCenterOfMassInBodyFrame(context) for b in bodies]
        names = [b.name() for b in bodies]
        out.append(
            _Finger(
                p_W_joint=chain.p_W_joint,
                a_W=chain.a_W,
                p_W_tip0=chain.p_W_tip0,
                p_W_com0=np.array(coms),
                mass=np.array([b.get_mass(context) for b in bodies]),
                p_W_link0=ends[i],
                link_joint=np.array([names.index(c.body) for c in capsules[i]]),
                link_radius=np.array([c.radius for c in capsules[i]]),
            )
        )
    return tuple(out)


@dataclass(frozen=True)
class SpaceHandModel:
    """What a segment's program needs of a SpaceScene (scene.spatial), in plain values: it pickles to a worker
    process, which then needs no plant of its own."""

    fingers: tuple  # (F,) scene.kinematics.SerialFinger: the chains, their joint limits and Jacobians
    chains: tuple[_Finger, ...]  # (F,) the chains with their links' masses (space_fingers)
    object: SpaceObject
    tip_radius: float  # m
    gravity: float  # m/s^2
    tau_max: np.ndarray  # (F, n) N m

    @property
    def num_fingers(self) -> int:
        return len(self.fingers)


def hand_model(scene) -> SpaceHandModel:
    """The SpaceHandModel of a SpaceScene."""
    return SpaceHandModel(
        fingers=tuple(scene.fingers),
        chains=space_fingers(scene),
        object=scene.object,
        tip_radius=float(scene.tip_radius),
        gravity=float(scene.gravity),
        tau_max=np.array(scene.tau_max, dtype=float),
    )


def refine_ik(finger, q0, target, lower, upper) -> np.ndarray:
    """Joint angles (..., n) near q0 that put the fingertip centre on `target` (..., 3): damped Newton steps
    within the limits (the nodes' IK holds the tips to 0.1 mm; the program pins them exactly)."""
    q = np.array(q0, dtype=float)
    for _ in range(NEWTON_ITERATIONS):
        points, axes, tip, _, _ = finger.chain(q)
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
        self.hand = _stacked(fingers)  # every finger at once
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
        parts = {name: Z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
        parts["lam"] = parts["lam"].reshape(self.K, lay.num_fingers, lay.edges)
        parts["q"] = parts["q"].reshape(self.K, lay.num_fingers, lay.joints)
        return parts

    def rotations(self, phi):
        return self.N @ _exp(phi)

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
        sign = np.where(x_B < 0, -1.0, 1.0)
        d = np.abs(x_B) - self.half
        out = np.maximum(d, 0.0)
        norm = np.linalg.norm(out, axis=-1, keepdims=True)
        face = np.eye(3)[np.argmax(d, axis=-1)]  # inside: the nearest face's axis
        g = np.where(norm > 0, out / np.where(norm > 0, norm, 1.0), face) * sign  # d value / d x_B
        x_W = (1 - t) * ends[..., 0, :] + t * ends[..., 1, :]  # (K, F, L, 3)
        lever = _cross(axes[:, :, None], x_W[:, :, :, None, :] - points[:, :, None])  # (K, F, L, n, 3)
        n = self.layout.joints
        turned = np.arange(n)[None, :] <= self.hand.link_joint[0][:, None]  # (L, n): joint k turns capsule l
        gR = np.einsum("kfli,kji->kflj", g, R)  # d value / d x_W
        dq = np.einsum("kflj,kflnj->kfln", gR, lever) * turned
        dphi = np.einsum("kfli,kflij->kflj", g, _skew(x_B) @ J_r[:, None, None])
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
        return _vee_skew(_exp(-self.h * w_mid) @ R[1:] @ np.swapaxes(R[:-1], -1, -2))

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
        u fixed in B turns as d(R u) = -R [u]x J_r dphi (_turned)."""
        lay = self.layout
        F, n, m = lay.num_fingers, lay.joints, lay.edges
        x, R, f_B, f_W, _, (tips, taus, J_tip, J_C, dtau_dq, axes) = self._knot(Z, True)
        rows = self._rows(x, R, f_B, f_W, tips, taus)
        J_r = _right_jacobian(x["phi"])
        phi, eye = lay.slice("phi"), np.eye(3)
        Jk = np.zeros(rows.shape + (lay.width,))
        Jk[:, 0:3, phi] = -_turned(R, J_r, f_B.sum(1))
        Jk[:, 3:6, phi] = -_turned(R, J_r, np.cross(self.p_BC, f_B).sum(1))
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            Jk[:, row : row + 3, lay.slice(name)] = eye
        # momentum L - R I R^T w: with a = R^T w, d(R I a) = R ([I a]x - I [a]x) J_r dphi + R I R^T dw
        a = np.einsum("kji,kj->ki", R, x["w"])
        Jk[:, 6:9, phi] = R @ (_skew(a @ self.inertia) - self.inertia @ _skew(a)) @ J_r / self.momentum_unit
        Jk[:, 6:9, lay.slice("w")] = -R @ self.inertia @ np.swapaxes(R, -1, -2) / self.momentum_unit
        edges_W = np.einsum("kij,kfej->kfei", R, self.edges_B)  # (K, F, m, 3)
        moments_W = np.einsum("kij,kfej->kfei", R, np.cross(self.p_BC[:, :, None, :], self.edges_B))
        lam0, q0 = lay.slice("lam").start, lay.slice("q").start
        pin_phi = -_turned(R, J_r, self.p_BC + self.r * self.n_B)  # (K, F, 3, 3)
        # tau_j = (a_j x (tip - r n_W - p_j)) . f_W: f_W and n_W turn with phi, d tau_j = J_C,j . df_W
        # - r (f_W x a_j) . dn_W
        tau_phi = J_C @ _turned(R, J_r, f_B) - self.r * _cross(f_W[:, :, None, :], axes) @ _turned(R, J_r, self.n_B)
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
        Jk[:, c, lay.slice("phi")] = np.einsum("ki,kij->kj", g, _skew(p_B) @ J_r)

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
        E = _exp(-self.h * w_mid)
        Q = E @ R[1:] @ np.swapaxes(R[:-1], -1, -2)
        left = np.stack([_vee_skew(B @ Q) for B in _BASIS_SKEW], -1)  # (K-1, 3, 3): u -> vee skew([u]x Q)
        right = np.stack([_vee_skew(Q @ B) for B in _BASIS_SKEW], -1)  # u -> vee skew(Q [u]x)
        dw = left @ E @ _right_jacobian(-self.h * w_mid) * (-0.5 * self.h)
        Jl = np.zeros((self.K - 1, 3, lay.width))
        Jr = np.zeros_like(Jl)
        Jl[:, :, lay.slice("phi")] = -right @ R[:-1] @ J_r[:-1]
        Jr[:, :, lay.slice("phi")] = left @ E @ R[1:] @ J_r[1:]
        Jl[:, :, lay.slice("w")] = Jr[:, :, lay.slice("w")] = dw
        return Jl, Jr


class _SegmentConstraint:
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


def _guess(rows: SpaceSegmentRows) -> np.ndarray:
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
    """One segment's program, its initial guess set (_guess)."""

    prog: MathematicalProgram
    z: np.ndarray  # (K, width) the knots' variables
    rows: SpaceSegmentRows
    binding: object  # the nonlinear rows (_SegmentConstraint) over z, knot after knot
    build_time_s: float


def _add_rule(prog, var: dict, rows, m: float) -> None:
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


def _add_costs(prog, var: dict, lay: _Layout, K: int) -> None:
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
    start = _guess(rows) if start is None else start
    rows = SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links, near_apart(rows, start))
    lay, K = rows.layout, rows.K
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, lay.width, "z")
    var = {name: z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
    m = scene.object.mass
    _add_rule(prog, var, rows, m)
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
    _add_costs(prog, var, lay, K)
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
    SpaceScene or its SpaceHandModel, `fingers` the chains of space_fingers."""
    program, result, Z, times = solve_with_link_retry(
        lambda links, Z: build_space_segment(scene, fingers, spec, mu, links, Z),
        lambda program, Z: max(link_depth(program.rows, Z), finger_overlap(program.rows, Z)),
        config,
    )
    return _segment_arrays(program.rows, Z, result, times)


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


def _segment_arrays(rows: SpaceSegmentRows, Z, result, times: tuple[float, float, float]) -> SpaceSegmentResult:
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


# -- general CITO in space: one program over the whole horizon --------------------------------------------------
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
        self.hand = _stacked(fingers)
        self.links = links
        F, n = scene.num_fingers, len(scene.fingers[0].q_lower)
        self.layout = _Layout(F, n, PYRAMID_EDGES)
        self.K, self.h = len(spec.N), dt
        self.N, self.w_nominal, self.n_B = spec.N, spec.w_nominal, spec.n_B
        n_W = np.einsum("kij,kfj->kfi", self.N, self.n_B)
        edges_W = pyramid_edges(n_W.reshape(-1, 3), mu, PYRAMID_EDGES).reshape(self.K, F, PYRAMID_EDGES, 3)
        self.edges_B = np.einsum("kji,kfej->kfei", self.N, edges_W)
        self.pinned = np.zeros((self.K, F), dtype=bool)
        self.gap_row, self.product_row, self.torque_row = 9, 9 + F, 9 + 2 * F
        self.link_row = self.torque_row + F * n
        self.inertia = scene.object.inertia
        self.half = scene.object.half
        self.momentum_unit = float(np.max(np.diag(self.inertia)))
        self.r, self.g = scene.tip_radius, scene.gravity
        self.tau_max = scene.tau_max
        self.mu = mu

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
        moment = x["T"] - _cross(arms, f_W).sum(1)
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
        J_r = _right_jacobian(x["phi"])
        phi, p, eye = lay.slice("phi"), lay.slice("p"), np.eye(3)
        Jk = np.zeros(rows.shape + (lay.width,))
        for row, name in ((0, "F"), (3, "T"), (6, "L")):
            Jk[:, row : row + 3, lay.slice(name)] = eye
        turned_f, turned_n = _turned(R, J_r, f_B), _turned(R, J_r, self.n_B)  # (K, F, 3, 3)
        arms = tips - x["p"][:, None, :] - self.r * n_W
        Jk[:, 0:3, phi] = -turned_f.sum(1)
        Jk[:, 3:6, phi] = -(self.r * _skew(f_W) @ turned_n + _skew(arms) @ turned_f).sum(1)
        Jk[:, 3:6, p] = -_skew(f_W.sum(1))
        a = np.einsum("kji,kj->ki", R, x["w"])  # the momentum's columns as SpaceSegmentRows.jacobians'
        Jk[:, 6:9, phi] = R @ (_skew(a @ self.inertia) - self.inertia @ _skew(a)) @ J_r / self.momentum_unit
        Jk[:, 6:9, lay.slice("w")] = -R @ self.inertia @ np.swapaxes(R, -1, -2) / self.momentum_unit
        edges_W = np.einsum("kij,kfej->kfei", R, self.edges_B)  # (K, F, m, 3)
        tips_B, gaps = self._gaps(x, R, tips)
        g = _box_distance_gradient(self.half, tips_B)  # (K, F, 3) d gap / d tips_B
        gR = np.einsum("kfi,kji->kfj", g, R)  # d gap / d tip in W
        g_phi = np.einsum("kfi,kfij->kfj", g, _skew(tips_B) @ J_r[:, None])
        normal = x["lam"].sum(-1)  # (K, F) N
        tau_phi = J_C @ turned_f - self.r * _cross(f_W[:, :, None, :], axes) @ turned_n
        lam0, q0 = lay.slice("lam").start, lay.slice("q").start
        for i in range(F):
            lam_i, q_i = slice(lam0 + m * i, lam0 + m * (i + 1)), slice(q0 + n * i, q0 + n * (i + 1))
            Jk[:, 0:3, lam_i] = -np.swapaxes(edges_W[:, i], -1, -2)
            Jk[:, 3:6, lam_i] = -np.swapaxes(_cross(arms[:, i, None, :], edges_W[:, i]), -1, -2)
            Jk[:, 3:6, q_i] = _skew(f_W[:, i]) @ J_tip[:, i]
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
        return (self.pair_values(Z), *self._pair_jacobians(x, R, _right_jacobian(x["phi"])))


def _box_distance_gradient(half, p_B) -> np.ndarray:
    """(..., 3) the gradient of geometry.box_signed_distances at p_B (..., 3): outside the unit vector from the
    nearest box point, inside the deepest face's normal."""
    sign = np.where(p_B < 0, -1.0, 1.0)
    d = np.abs(p_B) - half
    out = np.maximum(d, 0.0)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    face = np.eye(3)[np.argmax(d, axis=-1)]
    return np.where(norm > 0, out / np.where(norm > 0, norm, 1.0), face) * sign


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
    var = {name: z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
    _add_rule(prog, var, rows, scene.object.mass)
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
    _add_costs(prog, var, lay, K)
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
    return _segment_arrays(program.rows, Z, result, times)


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
    Z[:, lay.slice("F")], Z[:, lay.slice("T")] = f.sum(1), _cross(arms, f).sum(1)
    Z[:, lay.slice("L")] = (
        np.einsum("kij,jl,kml,km->ki", rows.N, rows.inertia, rows.N, rows.w_nominal) / rows.momentum_unit
    )
    return Z


def cito_cold_start(scene, fingers, node, goal_quaternion, mu: float):
    """(CitoSpec, knots' values (K, width)) of general CITO from the start grasp `node` (a SpaceContactNode) to
    the goal: the nominal is the straight slerp under one rest-to-rest time law (time_law) over as many segments
    as the search's path has (search.tree.space_object_path), and the guess the start grasp held: each fingertip
    kept on its contact as the cube turns (refine_ik, within the limits), the forces of the holding LP."""
    segments = len(space_object_path(goal_quaternion, node.object_pose)) - 1
    K = segments * SPACE_INTERVALS + 1
    R_a = quaternion_matrices(node.object_pose[:4])
    axis_angle = so3_log(quaternion_matrices(goal_quaternion) @ R_a.T)
    s, rate = time_law(K - 1)
    N = _exp(s[:, None] * axis_angle) @ R_a
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


# -- the joint formulation in space: the search's segments in one program ---------------------------------------
@dataclass(frozen=True)
class SpaceJointProgram:
    """The joint formulation's program: the segments' knots in one z, a node both one segment's last knot and the
    next one's first (joint_knots), the nodes free but the start and the goal."""

    prog: MathematicalProgram
    z: np.ndarray  # (S (K - 1) + 1, width)
    rows: tuple[SpaceSegmentRows, ...]  # per segment, over its knots of z
    build_time_s: float


def joint_knots(rows) -> list[slice]:
    """Each segment's knots in the joint program's z: segment s's first is segment s - 1's last."""
    step = rows[0].K - 1
    return [slice(s * step, s * step + r.K) for s, r in enumerate(rows)]


def _joint_bounds(rows: SpaceSegmentRows, s: int, num_segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Segment s's knot rows' bounds in the joint program: its first knot's rows are segment s - 1's last knot's
    (the same node, contacts and pyramids), left to that segment (unbounded: no redundant equality rows); a
    node inside the horizon is free, its links held off the box as the free knots' are."""
    lo, hi = rows.knot_bounds(free_last=s < num_segments - 1)
    if s > 0:
        lo[0], hi[0] = -np.inf, np.inf
    return lo, hi


def build_space_joint(
    scene, fingers, specs: list[SegmentSpec], mu: float, links: bool = False, start: np.ndarray | None = None
) -> SpaceJointProgram:
    """The joint formulation in space (the paper's): one program over the whole horizon with the search's contact
    plan: each segment's rows (SpaceSegmentRows: its contacts, its switching finger lifted) over its knots, the
    rule between every two knots, the start and the goal pinned as a segment's ends are (pose, rest, static,
    joints), every node between them free (phi within PHI_BOUND, moving, its joints within their limits); the
    segment program's costs once per knot. From `start` (knots, width), else from the segments' guesses."""
    t0 = time.perf_counter()
    rows = tuple(SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links) for spec in specs)
    knots = joint_knots(rows)
    if start is None:
        start = np.concatenate([_guess(rows[0]), *(_guess(r)[1:] for r in rows[1:])])
    rows = tuple(
        SpaceSegmentRows(scene, fingers, spec, mu, SPACE_INTERVALS, SPACE_DT, links, near_apart(r, start[k]))
        for spec, r, k in zip(specs, rows, knots)
    )
    lay, m = rows[0].layout, scene.object.mass
    K = knots[-1].stop
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(K, lay.width, "z")
    var = {name: z[:, lay.slice(name)] for name in (*_NAMES, "lam", "q")}
    for r, knot in zip(rows, knots):
        _add_rule(prog, {name: v[knot] for name, v in var.items()}, r, m)
    prog.AddBoundingBoxConstraint(-PHI_BOUND, PHI_BOUND, var["phi"][1:-1].ravel())
    for end, p in ((0, specs[0].p), (-1, specs[-1].p)):
        for name, value in (("phi", np.zeros(3)), ("p", p), ("w", np.zeros(3)), ("v", np.zeros(3))):
            prog.AddBoundingBoxConstraint(value, value, var[name][end])
        prog.AddBoundingBoxConstraint(np.r_[0.0, 0.0, m * rows[0].g], np.r_[0.0, 0.0, m * rows[0].g], var["F"][end])
        prog.AddBoundingBoxConstraint(np.zeros(3), np.zeros(3), var["T"][end])
    lam_hi = np.full((K, lay.num_fingers, lay.edges), np.inf)
    for spec, knot in zip(specs, knots):
        if spec.switching is not None:
            lam_hi[knot.start + 1 : knot.stop - 1, spec.switching] = 0.0
    prog.AddBoundingBoxConstraint(np.zeros(lam_hi.size), lam_hi.ravel(), var["lam"].ravel())
    lower = np.concatenate([c.q_lower for c in scene.fingers])
    upper = np.concatenate([c.q_upper for c in scene.fingers])
    prog.AddBoundingBoxConstraint(np.tile(lower, K - 2), np.tile(upper, K - 2), var["q"][1:-1].ravel())
    prog.AddBoundingBoxConstraint(specs[0].q_a.ravel(), specs[0].q_a.ravel(), var["q"][0])
    prog.AddBoundingBoxConstraint(specs[-1].q_b.ravel(), specs[-1].q_b.ravel(), var["q"][-1])
    for s, (r, knot) in enumerate(zip(rows, knots)):
        constraint = _SegmentConstraint(r)
        lo, hi = _joint_bounds(r, s, len(rows))
        pair = np.zeros(3 * (r.K - 1))
        binding = prog.AddConstraint(
            constraint,
            np.concatenate([lo.ravel(), pair]),
            np.concatenate([hi.ravel(), pair]),
            z[knot].ravel(),
            description=f"space segment {s}",
        )
        binding.evaluator().SetGradientSparsityPattern(constraint.sparsity())
    _add_costs(prog, var, lay, K)
    prog.SetInitialGuess(z, start)
    return SpaceJointProgram(prog, z, rows, time.perf_counter() - t0)


def solve_space_joint(
    scene, fingers, specs: list[SegmentSpec], mu: float, config: CitoConfig
) -> list[SpaceSegmentResult]:
    """The joint formulation built and solved by IPOPT (cito.solve's options), as a segment is, again with the link
    rows from its solution when a link then reaches over 1 mm into the box; the solution as one
    SpaceSegmentResult per segment (each with the one program's status and times)."""
    program, result, Z, times = solve_with_link_retry(
        lambda links, Z: build_space_joint(scene, fingers, specs, mu, links, Z),
        lambda program, Z: max(
            max(link_depth(r, Z[k]), finger_overlap(r, Z[k])) for r, k in zip(program.rows, joint_knots(program.rows))
        ),
        config,
    )
    return [_segment_arrays(r, Z[k], result, times) for r, k in zip(program.rows, joint_knots(program.rows))]
