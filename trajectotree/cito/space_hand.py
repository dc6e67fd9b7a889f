"""The kinematics of a hand in space in closed form, for the rows of its programs (cito.spatial's segments,
cito.space_cito, cito.space_joint): SO(3)'s exponential and right Jacobian, and each finger's serial chain in
plain arrays.

The object's orientation is R = N exp([phi]x) about a nominal N (Rodrigues' formula, its series near phi = 0).
It perturbs as R exp([J_r(phi) dphi]x), J_r the right Jacobian of SO(3), so a vector u fixed in B turns as
d(R u) = -R [u]x J_r dphi (turned).

A finger (Finger, from the plant by space_fingers) is its chain at zero angles: its joints' points p_j and axes
a_j, its fingertip centre, its links' centres of mass c_l and masses m_l and its link capsules' ends; at q, joint
j turns every point beyond it about its current axis. The hand is quasi-static: the motors' torques hold the
finger still against its own weight and push with f at the contact point c,

    tau_j = (a_j x (c - p_j)) . f + g sum_{l >= j} m_l e_z . (a_j x (c_l - p_j)),

the fingers' inertia left out (2-3 orders below the motors at these speeds); the fingertip's Jacobian and
dtau/dq are in closed form through the chain's axes and points (Finger.derivatives). refine_ik puts a fingertip
centre on a target (damped Newton steps within the joint limits); SpaceHandModel is what a segment's program
needs of a SpaceScene, in plain values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectotree.scene.spatial import SpaceObject

NEWTON_ITERATIONS = 50  # IK refinements of a fingertip onto its target (damped Newton, converges in ~5)


def skew(v):
    """[v]x (..., 3, 3) of v (..., 3): [v]x u = v x u."""
    z = np.zeros_like(v[..., 0])
    return np.stack(
        [np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
         np.stack([-v[..., 1], v[..., 0], z], -1)],
        axis=-2,
    )  # fmt: skip


def exp(phi):
    """exp([phi]x) (..., 3, 3) for phi (..., 3) (Rodrigues, series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = theta2 < 1e-10
    t2 = np.where(small, 1.0, theta2)
    theta = np.sqrt(t2)
    a = np.where(small, 1.0 - theta2 / 6 + theta2**2 / 120, np.sin(theta) / theta)
    b = np.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - np.cos(theta)) / t2)
    K = skew(phi)
    return np.eye(3) + a * K + b * (K @ K)


def right_jacobian(phi):
    """J_r(phi) (..., 3, 3): exp([phi + d]x) = exp([phi]x) exp([J_r d]x) to first order in d (series near 0)."""
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = theta2 < 1e-10
    t2 = np.where(small, 1.0, theta2)
    theta = np.sqrt(t2)
    a = np.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - np.cos(theta)) / t2)
    b = np.where(small, 1.0 / 6 - theta2 / 120 + theta2**2 / 5040, (theta - np.sin(theta)) / (t2 * theta))
    K = skew(phi)
    return np.eye(3) - a * K + b * (K @ K)


def turned(R, J_r, u):
    """d(R u)/dphi (K, ..., 3, 3) for u (K, ..., 3) fixed in B, R = N exp([phi]x) (K, 3, 3), J_r at phi:
    -R [u]x J_r."""
    shape = (len(R),) + (1,) * (u.ndim - 2) + (3, 3)
    return -R.reshape(shape) @ skew(u) @ J_r.reshape(shape)


def cross(a, b):
    """a x b over the last axis (numpy's cross costs more in axis handling than in arithmetic on these sizes)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def _rotate(axis, angle, v):
    """v (..., M, 3) turned by angle (...) about the unit axis (..., 3) (Rodrigues)."""
    a = axis[..., None, :]
    c, s = np.cos(angle)[..., None, None], np.sin(angle)[..., None, None]
    return v * c + cross(a, v) * s + a * np.sum(a * v, -1)[..., None] * (1 - c)


def vee_skew(M):
    """vee((M - M^T) / 2) (..., 3) of M (..., 3, 3)."""
    return 0.5 * np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1)


BASIS_SKEW = skew(np.eye(3))  # [e_i]x, i = 0..2


@dataclass(frozen=True)
class Finger:
    """A finger's chain at zero angles (scene.kinematics.SerialFinger) and its links' masses and centres of
    mass (link j beyond joint j), for forward kinematics and gravity torques; the arrays may carry a leading
    axis of fingers (stacked), all with the same number n of joints."""

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
        return np.sum(cross(axes, lever[..., None, :] - points) * f_W[..., None, :], -1)

    def _weight(self, axes, points, coms, gravity: float):
        # joint j carries links j..n-1: tau_j = sum_l m_l g e_z . (a_j x (c_l - p_j))
        moment = cross(axes[..., :, None, :], coms[..., None, :, :] - points[..., :, None, :])[..., 2]
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
        J_C = cross(axes, lever[..., None, :] - points)
        tau = np.sum(J_C * f_W[..., None, :], -1) + self._weight(axes, points, coms, gravity)
        U = cross(axes, tip[..., None, :] - points)  # (..., k, 3): d tip / d q_k
        a_j, a_k = axes[..., :, None, :], axes[..., None, :, :]  # (..., j, k, 3)
        before = np.tril(np.ones((n, n)), -1)[..., None]  # [j, k]: k < j
        to_tip = tip[..., None, :] - points  # (..., j, 3)
        inner = cross(cross(a_k, a_j), (lever[..., None, :] - points)[..., :, None, :]) + cross(
            a_j, cross(a_k, to_tip[..., :, None, :])
        )
        outer = cross(a_j, U[..., None, :, :])
        dpush = np.sum(np.where(before, inner, outer) * f_W[..., None, None, :], -1)
        # the weight: [j, k, l]
        rel = coms[..., None, :, :] - points[..., :, None, :]  # (..., i, l, 3): c_l - p_i
        rel_j, rel_k = rel[..., :, None, :, :], rel[..., None, :, :, :]  # (..., j, k, l, 3)
        A_j, A_k = axes[..., :, None, None, :], axes[..., None, :, None, :]
        inner_g = cross(cross(A_k, A_j), rel_j) + cross(A_j, cross(A_k, rel_j))
        outer_g = cross(A_j, cross(A_k, rel_k))
        jj, kk, ll = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
        gz = np.where((kk < jj)[..., None], inner_g, outer_g)[..., 2]
        carried = (ll >= jj) & (ll >= kk)  # link l carried by joint j and turned by joint k
        dweight = gravity * np.sum(gz * carried * self.mass[..., None, None, :], -1)
        return tip, tau, np.swapaxes(U, -1, -2), J_C, dpush + dweight, axes


def stacked(fingers) -> Finger:
    """The fingers as one Finger with a leading axis of fingers (the same number of joints each)."""
    return Finger(*(np.stack([getattr(f, name) for f in fingers]) for name in Finger.__dataclass_fields__))


def space_fingers(scene) -> tuple[Finger, ...]:
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
            Finger(
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
    chains: tuple[Finger, ...]  # (F,) the chains with their links' masses (space_fingers)
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
        J = np.swapaxes(cross(axes, tip[..., None, :] - points), -1, -2)  # (..., 3, n)
        JJt = J @ np.swapaxes(J, -1, -2) + 1e-8 * np.eye(3)
        q = np.clip(q + np.einsum("...ji,...j->...i", J, np.linalg.solve(JJt, error[..., None])[..., 0]), lower, upper)
    return q
