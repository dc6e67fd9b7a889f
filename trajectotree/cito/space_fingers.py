"""Finger-finger rows in space: two fingers of a hand in space keep apart in a segment's trajectory, as the
plane's (cito.fingers) keep them apart in the plane's.

The search in space keeps the fingers search.finger_clearance apart at its nodes only; between them the
switching finger lifts off and swings, and nothing else kept it out of the other fingers (seed-0 plans put two
fingertip spheres 9-14 mm inside each other, and the simulation's fingers collided there). Each finger is a
chain of parts, its links' collision capsules (scene.spatial.SpaceScene.link_capsules) and its fingertip
sphere (a capsule whose axis is a point, the fingertip centre), and each row is one part of finger a against
one part of finger b:

    |P(s*) - Q(t*)| - r_P - r_Q >= c,

P(s*), Q(t*) the nearest points of the two parts' axes (geometry.segment_segment_nearest), c = CLEARANCE.
The distance is the least over the two axes, so its derivative is that of |P - Q| at the nearest points held
fixed on their bodies (a minimum's envelope): d row = u . (dP - dQ), u the unit vector from Q to P, and a
point x on the body beyond joint j moves with joint k <= j as dx = a_k x (x - p_k) (the chain's joint axes
a_k and points p_k at the knot). Smooth wherever the axes are apart and their nearest points unique.

Which rows (`near_parts`): the pairs of parts that come within NEAR_MARGIN of each other over the knots of
the program's initial guess (its nodes, the holding fingers' interpolation and the switching finger's lifted
path), since most parts of most pairs stay far apart (over the 91 segments of 12 seed-0 plans, 0-7 pairs of
parts, 2.3 on average, came that near in the solution, of the 96 of four fingers).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from trajectotree.geometry import capsule_distances, segment_segment_nearest

# m, the least gap of two fingers' parts on the free knots (less where a node already has them closer): the
# executed swing strays 2-3 mm from the plan's path, and with 2 mm (the search's at its nodes) seed-0 goal 5's
# fingertips met in simulation and dropped the cube; with 5 mm it held
CLEARANCE = 0.005
# m, a pair of parts gets a row when it comes within this over the guess's knots: the trajectory's swinging
# finger leaves the guess's lifted path by about its 10 mm lift (cito.spatial.SWITCH_CLEARANCE), twice that
NEAR_MARGIN = 0.02


@dataclass(frozen=True)
class FingerParts:
    """A hand's fingers as chains of parts (its link capsules, then its fingertip sphere) for the rows."""

    owner: np.ndarray  # (P,) the last joint that turns each part (the fingertip: the last joint)
    radius: np.ndarray  # (P,) m

    @staticmethod
    def of(hand, tip_radius: float) -> FingerParts:
        """The parts of the stacked chains `hand` (cito.space_hand.Finger with a leading axis of fingers)."""
        n = hand.a_W.shape[-2]
        link_joint, link_radius = np.asarray(hand.link_joint)[0], np.asarray(hand.link_radius)[0]
        return FingerParts(np.r_[link_joint, n - 1].astype(int), np.r_[link_radius, tip_radius].astype(float))

    def ends(self, tip, link_ends) -> np.ndarray:
        """(K, F, P, 2, 3) m: each part's axis ends from the chain's fingertip centres tip (K, F, 3) and capsule
        ends (K, F, L, 2, 3)."""
        point = np.repeat(tip[:, :, None, None, :], 2, axis=3)
        return np.concatenate([link_ends, point], axis=2)


def all_part_pairs(num_fingers: int, num_parts: int) -> np.ndarray:
    """(R, 4) int: every (finger a, part i, finger b, part j), a < b."""
    return np.array(
        [
            (a, i, b, j)
            for a, b in itertools.combinations(range(num_fingers), 2)
            for i, j in itertools.product(range(num_parts), repeat=2)
        ],
        dtype=int,
    ).reshape(-1, 4)


def part_distances(parts: FingerParts, ends: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(K, R) m: the signed distances of the part pairs `pairs` (R, 4) at the part ends (K, F, P, 2, 3)."""
    a, i, b, j = pairs.T
    A, B = ends[:, a, i], ends[:, b, j]
    return capsule_distances(A[..., 0, :], A[..., 1, :], parts.radius[i], B[..., 0, :], B[..., 1, :], parts.radius[j])


def near_parts(parts: FingerParts, ends: np.ndarray, margin: float = NEAR_MARGIN) -> np.ndarray:
    """(R, 4): the part pairs (a, i, b, j), a < b, within `margin` m of each other at some knot of `ends`."""
    pairs = all_part_pairs(ends.shape[1], ends.shape[2])
    return pairs[part_distances(parts, ends, pairs).min(axis=0) < margin]


@dataclass(frozen=True)
class SpaceFingerRows:
    """The finger-finger rows of the part pairs `pairs` (R, 4: finger a, part i, finger b, part j, a < b)."""

    parts: FingerParts
    pairs: np.ndarray  # (R, 4) int

    @property
    def num_rows(self) -> int:
        return len(self.pairs)

    def values(self, tip, link_ends) -> np.ndarray:
        """(K, R) m at the chain's fingertip centres (K, F, 3) and capsule ends (K, F, L, 2, 3)."""
        return part_distances(self.parts, self.parts.ends(tip, link_ends), self.pairs)

    def jacobians(self, points, axes, tip, link_ends) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(values (K, R), d row / d q_a (K, R, n), d row / d q_b (K, R, n)) at the chain's joint points and
        axes (K, F, n, 3) and its fingertip centres and capsule ends: u . dP - u . dQ at the nearest points."""
        a, i, b, j = self.pairs.T
        ends = self.parts.ends(tip, link_ends)
        A, B = ends[:, a, i], ends[:, b, j]  # (K, R, 2, 3)
        s, t = segment_segment_nearest(A[..., 0, :], A[..., 1, :], B[..., 0, :], B[..., 1, :])
        P = A[..., 0, :] + s[..., None] * (A[..., 1, :] - A[..., 0, :])
        Q = B[..., 0, :] + t[..., None] * (B[..., 1, :] - B[..., 0, :])
        gap = P - Q
        dist = np.linalg.norm(gap, axis=-1)
        u = gap / np.maximum(dist, 1e-12)[..., None]
        values = dist - self.parts.radius[i] - self.parts.radius[j]
        return values, self._moved(points, axes, a, i, P, u), -self._moved(points, axes, b, j, Q, u)

    def _moved(self, points, axes, finger, part, x, u) -> np.ndarray:
        """(K, R, n): u . dx / dq_k = u . a_k x (x - p_k) for the joints k that turn the part, else 0."""
        lever = np.cross(axes[:, finger], x[:, :, None, :] - points[:, finger])  # (K, R, n, 3)
        n = axes.shape[-2]
        turned = np.arange(n)[None, :] <= self.parts.owner[part][:, None]  # (R, n)
        return np.einsum("krnc,krc->krn", lever, u) * turned


def least_part_distance(parts: FingerParts, ends: np.ndarray) -> float:
    """m, the least signed distance of any two fingers' parts at any knot of `ends` (K, F, P, 2, 3)."""
    pairs = all_part_pairs(ends.shape[1], ends.shape[2])
    return float(part_distances(parts, ends, pairs).min(initial=np.inf))
