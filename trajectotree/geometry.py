"""The box boundary in its own frame B (numpy only).

Arclength s runs counter-clockwise along the boundary, starting at the corner
(+w/2, -h/2): first up the right face (length h), then left along the top (w),
down the left face (h) and right along the bottom (w). The perimeter is
2 (w + h); every function takes s modulo the perimeter.

A contact frame at s is (n_B, t_B): the outward unit normal of the face and the
counter-clockwise unit tangent t_B = z x n_B.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BoxBoundary:
    width: float   # m, extent along B's x axis
    height: float  # m, extent along B's y axis

    @property
    def perimeter(self) -> float:
        return 2.0 * (self.width + self.height)

    def _faces(self):
        """(start corner, unit direction, length, outward normal) of each face, in s order."""
        a, b = self.width / 2, self.height / 2
        return (
            (np.array([a, -b]), np.array([0.0, 1.0]), self.height, np.array([1.0, 0.0])),
            (np.array([a, b]), np.array([-1.0, 0.0]), self.width, np.array([0.0, 1.0])),
            (np.array([-a, b]), np.array([0.0, -1.0]), self.height, np.array([-1.0, 0.0])),
            (np.array([-a, -b]), np.array([1.0, 0.0]), self.width, np.array([0.0, -1.0])),
        )

    def corner_arclengths(self) -> np.ndarray:
        """Arclengths of the four corners: 0, h, h + w, 2h + w."""
        h, w = self.height, self.width
        return np.array([0.0, h, h + w, 2 * h + w])

    def point(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Contact point p_BC and outward unit normal n_B at arclength s."""
        s = float(s) % self.perimeter
        for start, direction, length, normal in self._faces():
            if s <= length:
                return start + s * direction, normal.copy()
            s -= length
        start, direction, length, normal = self._faces()[-1]
        return start + length * direction, normal.copy()  # s == perimeter up to rounding

    def tangent(self, s: float) -> np.ndarray:
        """Counter-clockwise unit tangent t_B = z x n_B at arclength s."""
        _, n = self.point(s)
        return np.array([-n[1], n[0]])

    def arclength(self, p_B) -> float:
        """Arclength of the boundary point nearest to p_B."""
        p = self.project(p_B)
        s0 = 0.0
        best, best_s = np.inf, 0.0
        for start, direction, length, _ in self._faces():
            t = np.clip(np.dot(p - start, direction), 0.0, length)
            d = np.linalg.norm(start + t * direction - p)
            if d < best - 1e-15:
                best, best_s = d, s0 + t
            s0 += length
        return best_s % self.perimeter

    def project(self, p_B) -> np.ndarray:
        """The boundary point nearest to p_B."""
        p = np.asarray(p_B, dtype=float)
        a, b = self.width / 2, self.height / 2
        if abs(p[0]) <= a and abs(p[1]) <= b:  # inside: push out through the nearest face
            gaps = np.array([a - p[0], b - p[1], a + p[0], b + p[1]])
            k = int(np.argmin(gaps))
            q = p.copy()
            q[k % 2] = (a, b, -a, -b)[k]
            return q
        return np.array([np.clip(p[0], -a, a), np.clip(p[1], -b, b)])

    def corner_distance(self, s: float) -> float:
        """Arclength distance from s to the nearest corner."""
        s = float(s) % self.perimeter
        d = np.abs(self.corner_arclengths() - s)
        return float(np.min(np.minimum(d, self.perimeter - d)))

    def signed_distance(self, p_B) -> float:
        """Exact signed distance from p_B to the box (negative inside)."""
        p = np.asarray(p_B, dtype=float)
        q = np.abs(p) - np.array([self.width / 2, self.height / 2])
        outside = np.linalg.norm(np.maximum(q, 0.0))
        inside = min(max(q[0], q[1]), 0.0)
        return float(outside + inside)


def rotation_2d(theta: float) -> np.ndarray:
    """R_WB for a rotation by theta about z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def box_to_world(pose, p_B) -> np.ndarray:
    """p_W of a point p_B given the object pose (x, y, theta)."""
    return np.asarray(pose[:2], dtype=float) + rotation_2d(pose[2]) @ np.asarray(p_B, dtype=float)


def world_to_box(pose, p_W) -> np.ndarray:
    """p_B of a point p_W given the object pose (x, y, theta)."""
    return rotation_2d(pose[2]).T @ (np.asarray(p_W, dtype=float) - np.asarray(pose[:2], dtype=float))


# ---- vectorized, for whole trajectories (physics check, execution schedule) ----------------

def rotations_2d(theta: np.ndarray) -> np.ndarray:
    """R_WB (K, 2, 2) for rotations by theta (K,) about z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def poses_world_to_box(x: np.ndarray, p_W: np.ndarray) -> np.ndarray:
    """p_B (K, P, 2) of world points p_W (K, P, 2) at object poses x (K, 3)."""
    return np.einsum("kba,kpb->kpa", rotations_2d(x[:, 2]), p_W - x[:, None, :2])


def poses_box_to_world(x: np.ndarray, p_B: np.ndarray) -> np.ndarray:
    """p_W (K, P, 2) of box points p_B (K, P, 2) at object poses x (K, 3)."""
    return x[:, None, :2] + np.einsum("kab,kpb->kpa", rotations_2d(x[:, 2]), p_B)


def box_signed_distance(p_B: np.ndarray, width: float, height: float) -> np.ndarray:
    """Exact signed distance (...,) of points p_B (..., 2) to the box (negative inside)."""
    q = np.abs(p_B) - np.array([width / 2, height / 2])
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def nearest_box_points(p_B: np.ndarray, width: float, height: float) -> np.ndarray:
    """The box-boundary point (..., 2) nearest to each p_B (..., 2), in B."""
    half = np.array([width / 2, height / 2])
    clipped = np.clip(p_B, -half, half)
    inside = np.all(np.abs(p_B) < half, axis=-1)
    # Inside: out through the nearest face, along the axis with the smallest gap to its face.
    axis = np.argmin(half - np.abs(p_B), axis=-1)
    sign = np.where(p_B >= 0, 1.0, -1.0)
    pushed = np.where(np.arange(2) == axis[..., None], sign * half, p_B)
    return np.where(inside[..., None], pushed, clipped)
