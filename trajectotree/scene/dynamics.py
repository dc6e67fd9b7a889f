"""The hand's two-link fingers' dynamics in closed form (`HandModel`), vectorized over fingers: what
CITO's programs and the grasp controller both use.

Everything here is read from the plant through `scene.FingerGeometry`, so the
SDF stays the single source of truth; tests compare these against the plant
(`CalcMassMatrix`, `CalcGravityGeneralizedForces`, frame kinematics).
Coriolis and centrifugal terms are omitted, as in the paper (eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectotree.scene.kinematics import TwoLinkFinger
from trajectotree.scene.plant import Scene


def _per_finger(q: np.ndarray) -> np.ndarray:
    """(..., 2F) joint angles as (..., F, 2)."""
    return q.reshape(q.shape[:-1] + (-1, 2))


@dataclass(frozen=True)
class HandModel:
    """Per-finger parameters as arrays with a leading finger axis (F, ...); the
    kinematics are the fingers' `TwoLinkFinger` stack."""

    fingers: TwoLinkFinger  # (F, ...) p_W_base, psi, l1, l2, joint limits
    mass_a: np.ndarray  # (F,) kg m^2, M11 = a + 2 b cos q2
    mass_b: np.ndarray  # (F,) kg m^2, M12 = c + b cos q2
    mass_c: np.ndarray  # (F,) kg m^2, M22 = c
    grav_1: np.ndarray  # (F,) N m, g (m1 c1 + m2 l1): gravity moment of link 1 terms
    grav_2: np.ndarray  # (F,) N m, g m2 c2
    tau_max: np.ndarray  # (2F,) N m

    @staticmethod
    def from_scene(scene: Scene) -> HandModel:
        return HandModel.from_fingers(scene.fingers, scene.config.gravity)

    @staticmethod
    def from_fingers(f, g: float) -> HandModel:
        """The model of the fingers' geometries `f` (scene.fingers) under gravity g m/s^2."""
        m1, m2 = (np.array([fi.masses[j] for fi in f]) for j in (0, 1))
        c1, c2 = (np.array([fi.coms[j] for fi in f]) for j in (0, 1))
        i1, i2 = (np.array([fi.inertias[j] for fi in f]) for j in (0, 1))
        l1 = np.array([fi.l1 for fi in f])
        return HandModel(
            fingers=TwoLinkFinger.stack(f),
            mass_a=i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2),
            mass_b=m2 * l1 * c2,
            mass_c=i2 + m2 * c2**2,
            grav_1=np.array([fi.gravity_gains(g)[0] for fi in f]),
            grav_2=np.array([fi.gravity_gains(g)[1] for fi in f]),
            tau_max=np.concatenate([fi.tau_max for fi in f]),
        )

    @property
    def q_lower(self) -> np.ndarray:
        """(2F,) rad, finger-major."""
        return self.fingers.q_lower.ravel()

    @property
    def q_upper(self) -> np.ndarray:
        """(2F,) rad, finger-major."""
        return self.fingers.q_upper.ravel()

    def angles(self, q: np.ndarray):
        """(a1, a12): absolute angles of link 1 and link 2, each (..., 4), from q (..., 8)."""
        return self.fingers.angles(_per_finger(q))

    def links(self, q: np.ndarray):
        """(r1, r2): link vectors l1 e(a1) and l2 e(a12), each (..., 4, 2)."""
        return self.fingers.links(_per_finger(q))

    def fingertips(self, q: np.ndarray) -> np.ndarray:
        """p_WF (..., 4, 2), the fingertip sphere centres."""
        return self.fingers.fingertip(_per_finger(q))

    def jacobians(self, q: np.ndarray) -> np.ndarray:
        """J_WF (..., 4, 2, 2)."""
        return self.fingers.jacobian(_per_finger(q))

    def mass_matrices(self, q: np.ndarray) -> np.ndarray:
        """M (..., 4, 2, 2), each finger's joint-space mass matrix."""
        c2 = np.cos(_per_finger(q)[..., 1])
        m12 = self.mass_c + self.mass_b * c2
        return np.stack(
            [
                np.stack([self.mass_a + 2 * self.mass_b * c2, m12], -1),
                np.stack([m12, np.broadcast_to(self.mass_c, c2.shape)], -1),
            ],
            -2,
        )

    def gravity_forces(self, q: np.ndarray) -> np.ndarray:
        """tau_g (..., 4, 2): generalized gravity forces (positive where gravity accelerates q)."""
        a1, a12 = self.angles(q)
        t2 = -self.grav_2 * np.cos(a12)
        return np.stack([-self.grav_1 * np.cos(a1) + t2, t2], axis=-1)

    def gravity_derivatives(self, q: np.ndarray) -> np.ndarray:
        """d tau_g / d q (..., 4, 2, 2)."""
        a1, a12 = self.angles(q)
        d2 = self.grav_2 * np.sin(a12)
        d1 = self.grav_1 * np.sin(a1) + d2
        return np.stack([np.stack([d1, d2], -1), np.stack([d2, d2], -1)], -2)

    def mass_derivatives(self, q: np.ndarray) -> np.ndarray:
        """d M / d q2 (..., 4, 2, 2) (M does not depend on q1)."""
        s2 = np.sin(_per_finger(q)[..., 1])
        return np.stack(
            [
                np.stack([-2 * self.mass_b * s2, -self.mass_b * s2], -1),
                np.stack([-self.mass_b * s2, np.zeros_like(s2)], -1),
            ],
            -2,
        )

    def ik(self, i: int, p_WF: np.ndarray) -> np.ndarray | None:
        """Closed-form IK of finger i: the elbow branch q2 > 0 (the joint limits' side), the
        limits widened by 1e-9 rad (a node's own joint angles may sit on a limit to rounding);
        None when the point is out of reach or the solution violates the limits."""
        return self.fingers.finger(i).ik_one(p_WF, elbow=1, tolerance=1e-9)

    def ik_many(self, i: int, p_WF: np.ndarray) -> np.ndarray:
        """`ik` of finger i for targets (..., 2) at once: (..., 2), NaN rows where `ik` gives None."""
        return self.fingers.finger(i).ik(p_WF, elbow=1, tolerance=1e-9)
