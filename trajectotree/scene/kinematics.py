"""Closed-form kinematics of the planar two-link fingers: the one home of FK, the
fingertip Jacobian and IK (tests/test_kinematics.py checks them against the plant).

A finger (frame conventions of scene.py): joint 1 at p_W_base, link 1 of length l1 at
absolute angle a1 = psi + q1, link 2 of length l2 (joint 2 to the fingertip-sphere
centre F) at a12 = a1 + q2:

    r1 = l1 (cos a1, sin a1),  r2 = l2 (cos a12, sin a12)
    p_WF = p_W_base + r1 + r2,  J_WF = d p_WF / d q = [K (r1 + r2), K r2]

with K the +90 degree rotation. A `TwoLinkFinger` holds one finger (scalar psi, l1, l2)
or several (arrays with a leading finger axis); the numpy methods broadcast joint angles
q (..., 2) against it. `links_one` is FK for one finger in Python floats by `math`, for
the scalar hot paths (CITO's one-knot values, the search's collision test).

IK, one solver (`ik_candidates`, vectorized over targets) behind every query: the candidates
are the elbow-positive branch q2 = +acos(c2) first, then q2 = -acos(c2), each with q1 wrapped
into [-pi, pi) and then shifted by -2 pi, 0, +2 pi (joint limits may exceed pi); a candidate
is a solution when it lies within [q_lower - tolerance, q_upper + tolerance] (tolerance 0 by
default). An unreachable target (|c2| > 1, or no candidate within the limits) gives no
solution: [] from `ik_solutions`, a NaN row from `ik`, None from `ik_one`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

# K90 @ v rotates a planar vector by +90 degrees: K v = z x v.
K90 = np.array([[0.0, -1.0], [1.0, 0.0]])
# Shifts of the wrapped q1 tried by IK, in candidate order.
Q1_WRAPS = (-2 * np.pi, 0.0, 2 * np.pi)
ELBOW_BRANCHES = (1, -1)  # sign of q2 per branch, in candidate order


def jacobian_from_links(r1, r2) -> np.ndarray:
    """J_WF (..., 2, 2) = [K (r1 + r2), K r2] from link vectors r1, r2 (..., 2)."""
    return np.stack([(r1 + r2) @ K90.T, r2 @ K90.T], axis=-1)


def first_solution(candidates: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The first valid candidate per target: candidates (C, ..., 2), valid (C, ...) ->
    (..., 2), NaN where none is valid."""
    out = np.full(candidates.shape[1:], np.nan)
    found = valid.any(axis=0)
    out[found] = np.take_along_axis(candidates, np.argmax(valid, axis=0)[None, ..., None], axis=0)[0][found]
    return out


@dataclass(frozen=True)
class TwoLinkFinger:
    """The kinematic parameters of one finger (scalars) or of several (leading finger axis)."""

    p_W_base: np.ndarray  # (..., 2) m, joint-1 axis position in W
    psi: float  # (...) rad, direction of link 1 in W when q1 = 0
    l1: float  # (...) m, joint 1 to joint 2
    l2: float  # (...) m, joint 2 to fingertip centre
    q_lower: np.ndarray  # (..., 2) rad, joint lower limits
    q_upper: np.ndarray  # (..., 2) rad, joint upper limits

    @staticmethod
    def stack(fingers) -> TwoLinkFinger:
        """Several fingers as one, each parameter an array with a leading finger axis."""
        return TwoLinkFinger(
            **{f.name: np.array([getattr(fi, f.name) for fi in fingers]) for f in fields(TwoLinkFinger)}
        )

    def finger(self, i: int) -> TwoLinkFinger:
        """Finger i of a stack."""
        return TwoLinkFinger(**{f.name: getattr(self, f.name)[i] for f in fields(TwoLinkFinger)})

    # -- forward kinematics -----------------------------------------------------------------
    def angles(self, q):
        """(a1, a12): absolute angles of link 1 and link 2 in W, each (...), from q (..., 2)."""
        q = np.asarray(q)
        a1 = self.psi + q[..., 0]
        return a1, a1 + q[..., 1]

    def links(self, q):
        """(r1, r2): the link vectors l1 e(a1), l2 e(a12), each (..., 2)."""
        a1, a12 = self.angles(q)
        r1 = np.asarray(self.l1)[..., None] * np.stack([np.cos(a1), np.sin(a1)], axis=-1)
        r2 = np.asarray(self.l2)[..., None] * np.stack([np.cos(a12), np.sin(a12)], axis=-1)
        return r1, r2

    def tip_from_links(self, r1, r2) -> np.ndarray:
        """p_WF (..., 2) = p_W_base + r1 + r2 from the link vectors."""
        return self.p_W_base + r1 + r2

    def fingertip(self, q) -> np.ndarray:
        """p_WF (..., 2), the fingertip centre in W at joint angles q (..., 2)."""
        return self.tip_from_links(*self.links(q))

    def links_one(self, q1: float, q2: float):
        """(a1, a12, r1, r2) of one finger at Python-float joint angles, r1 and r2 as (x, y)
        pairs of floats, by `math` (the scalar hot paths: CITO's one-knot values, the
        search's collision test); `links` in scalars."""
        a1 = self.psi + q1
        a12 = a1 + q2
        return (
            a1,
            a12,
            (self.l1 * math.cos(a1), self.l1 * math.sin(a1)),
            (self.l2 * math.cos(a12), self.l2 * math.sin(a12)),
        )

    def elbow(self, q) -> np.ndarray:
        """p_W of joint 2 (..., 2)."""
        return self.p_W_base + self.links(q)[0]

    def jacobian(self, q) -> np.ndarray:
        """J_WF (..., 2, 2) = d p_WF / d q."""
        return jacobian_from_links(*self.links(q))

    # -- inverse kinematics, vectorized (numpy) ---------------------------------------------
    def ik_candidates(self, p_WF, *, tolerance: float = 0.0):
        """(candidates (6, ..., 2), valid (6, ...)) for targets p_WF (..., 2), in the module's
        candidate order; valid: reachable and within the limits widened by `tolerance` (rad)."""
        d = np.asarray(p_WF, dtype=float) - self.p_W_base
        dd = np.sum(d * d, axis=-1)
        c2 = (dd - self.l1**2 - self.l2**2) / (2 * self.l1 * self.l2)
        acos = np.arccos(np.clip(c2, -1.0, 1.0))
        candidates = []
        for sign in ELBOW_BRANCHES:
            q2 = sign * acos
            q1 = (
                np.arctan2(d[..., 1], d[..., 0])
                - self.psi
                - np.arctan2(self.l2 * np.sin(q2), self.l1 + self.l2 * np.cos(q2))
            )
            q1 = np.remainder(q1 + np.pi, 2 * np.pi) - np.pi
            candidates += [np.stack([q1 + wrap, np.broadcast_to(q2, q1.shape)], axis=-1) for wrap in Q1_WRAPS]
        candidates = np.stack(candidates)
        lower, upper = np.asarray(self.q_lower) - tolerance, np.asarray(self.q_upper) + tolerance
        valid = (np.abs(c2) <= 1.0)[None] & np.all((candidates >= lower) & (candidates <= upper), axis=-1)
        return candidates, valid

    def ik(self, p_WF, *, elbow: int = 0, tolerance: float = 0.0) -> np.ndarray:
        """Joint angles (..., 2) that put the fingertip centre at p_WF (..., 2): the first
        solution in candidate order, NaN where there is none. elbow=+1 or -1 keeps only
        that branch (sign of q2), 0 both."""
        candidates, valid = self.ik_candidates(p_WF, tolerance=tolerance)
        if elbow:
            valid[np.repeat(ELBOW_BRANCHES, len(Q1_WRAPS)) != elbow] = False
        return first_solution(candidates, valid)

    def ik_one(self, p_WF, **options) -> np.ndarray | None:
        """`ik` for one target (2,): the joint angles (2,), or None when there is no solution."""
        q = self.ik(p_WF, **options)
        return None if np.isnan(q[0]) else q

    def ik_solutions(self, p_WF) -> list[np.ndarray]:
        """Every solution (2,) within the joint limits for one target (2,) of one finger, in
        candidate order, each once (at full stretch both branches are q2 = 0); [] when there is none."""
        candidates, valid = self.ik_candidates(p_WF)
        solutions = []
        for q in candidates[valid]:
            if not any(np.array_equal(q, s) for s in solutions):
                solutions.append(q)
        return solutions


def rotate_about(axis: np.ndarray, angle, v: np.ndarray) -> np.ndarray:
    """Rodrigues: v (..., 3) turned by `angle` (...) rad about the unit `axis` (..., 3)."""
    angle = np.asarray(angle)[..., None]
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1 - c)


@dataclass(frozen=True)
class SerialFinger:
    """A finger in space: a chain of revolute joints, in the product-of-exponentials form. At zero
    joint angles joint j passes through p_W_joint[j] (m) along the unit axis a_W[j], and the
    fingertip sphere's centre F is at p_W_tip0 (all in W); turning joint j by q_j turns everything
    beyond it about that axis, so

        p_WF(q) = T_1(q_1) T_2(q_2) ... T_n(q_n) p_W_tip0,  T_j(q) p = c_j + Rot(a_j, q) (p - c_j),
        J_WF[:, j] = a'_j x (p_WF - c'_j)

    with a'_j, c'_j joint j's axis and point after the joints before it have turned. Read from the
    plant at zero joint angles (scene.spatial), so the SDF stays the source of truth."""

    p_W_joint: np.ndarray  # (n, 3) m
    a_W: np.ndarray  # (n, 3) unit axes
    p_W_tip0: np.ndarray  # (3,) m, the fingertip centre at q = 0
    q_lower: np.ndarray  # (n,) rad
    q_upper: np.ndarray  # (n,) rad

    def frames(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(c' (..., n, 3), a' (..., n, 3), p_WF (..., 3)): each joint's point and axis, and the
        fingertip centre, at joint angles q (..., n)."""
        q = np.asarray(q, dtype=float)
        n = len(self.a_W)
        points = np.broadcast_to(self.p_W_joint, q.shape[:-1] + (n, 3)).copy()
        axes = np.broadcast_to(self.a_W, q.shape[:-1] + (n, 3)).copy()
        tip = np.broadcast_to(self.p_W_tip0, q.shape[:-1] + (3,)).copy()
        for j in range(n):  # joint j turns the joints beyond it and the tip about its current axis
            c, a, angle = points[..., j, :], axes[..., j, :], q[..., j]
            tip = c + rotate_about(a, angle, tip - c)
            for k in range(j + 1, n):
                points[..., k, :] = c + rotate_about(a, angle, points[..., k, :] - c)
                axes[..., k, :] = rotate_about(a, angle, axes[..., k, :])
        return points, axes, tip

    def fingertip(self, q) -> np.ndarray:
        """p_WF (..., 3), the fingertip centre in W at joint angles q (..., n)."""
        return self.frames(q)[2]

    def jacobian(self, q, p_FQ_W=None) -> np.ndarray:
        """J_WQ (..., 3, n) = d p_WQ / d q of the point Q fixed on the last link at p_FQ_W (..., 3, in W,
        from the fingertip centre; default 0: Q = F), e.g. a contact point -r n from the centre."""
        points, axes, tip = self.frames(q)
        p_WQ = tip if p_FQ_W is None else tip + np.asarray(p_FQ_W, dtype=float)
        return np.swapaxes(np.cross(axes, p_WQ[..., None, :] - points), -1, -2)
