"""How far apart two fingers are: exact planar signed distances between their collision shapes.

A finger's collision geometry is its link boxes (`FingerGeometry.link_boxes`, a `LinkRectangle`
per link or None) and its fingertip sphere (radius r at the tip frame). All of it is centred on
the z = 0 plane, so two shapes' 3D distance is their planar one while they are apart, and their
planar overlap is 3D overlap (tests/search/test_finger_clearance.py checks both against
SceneGraph's signed-distance query). Here, in the plane and vectorized over K configurations:

- a disc against a disc: |c_a - c_b| - r_a - r_b;
- a disc against a convex polygon: the centre's signed distance to it, minus r (outside: the
  nearest edge's point-segment distance; inside: minus the depth to the nearest edge's line);
- two convex polygons: apart (an edge normal of either separates them), the least
  vertex-to-edge distance either way; overlapping, minus the least overlap of their projections
  on those normals (the exact penetration depth of two convex polygons).

Numpy only: the search (its stances and initial grasps), the physics check and the measurement
scripts share it; CITO's smooth rows (cito/fingers.py) are its conservative, differentiable twin.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np


def _edges(poly: np.ndarray):
    """(start vertices, edge vectors, outward unit normals) of counter-clockwise polygons (K, n, 2)."""
    e = np.roll(poly, -1, axis=-2) - poly
    n = np.stack([e[..., 1], -e[..., 0]], axis=-1)
    return poly, e, n / np.linalg.norm(n, axis=-1, keepdims=True)


def _point_segment_distances(p: np.ndarray, a: np.ndarray, e: np.ndarray) -> np.ndarray:
    """|p - nearest point of the segments a + t e, t in [0, 1]|: p (K, m, 2) against (K, n, 2) -> (K, m, n)."""
    d = p[..., :, None, :] - a[..., None, :, :]
    t = np.clip(np.einsum("...mnc,...nc->...mn", d, e) / np.einsum("...nc,...nc->...n", e, e)[..., None, :], 0, 1)
    return np.linalg.norm(d - t[..., None] * e[..., None, :, :], axis=-1)


def point_polygon_distance(p, poly) -> np.ndarray:
    """(K,) m, signed distance of points p (K, 2) to convex counter-clockwise polygons (K, n, 2):
    positive outside, minus the depth inside."""
    p = np.asarray(p, dtype=float)
    a, e, n = _edges(np.asarray(poly, dtype=float))
    inside = np.einsum("...nc,...nc->...n", p[..., None, :] - a, n).max(axis=-1)
    outside = _point_segment_distances(p[..., None, :], a, e)[..., 0, :].min(axis=-1)
    return np.where(inside <= 0.0, inside, outside)


def polygon_distance(A, B) -> np.ndarray:
    """(K,) m, signed distance between convex counter-clockwise polygons A (K, n, 2) and B (K, m, 2):
    the gap while apart, minus the penetration depth while they overlap."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    a, ea, na = _edges(A)
    b, eb, nb = _edges(B)
    axes = np.concatenate([na, nb], axis=-2)  # (K, n + m, 2)
    pa, pb = np.einsum("...vc,...xc->...vx", A, axes), np.einsum("...vc,...xc->...vx", B, axes)
    overlap = np.minimum(pa.max(axis=-2) - pb.min(axis=-2), pb.max(axis=-2) - pa.min(axis=-2))  # (K, n + m)
    depth = overlap.min(axis=-1)
    gap = np.minimum(
        _point_segment_distances(A, b, eb).min(axis=(-2, -1)), _point_segment_distances(B, a, ea).min(axis=(-2, -1))
    )
    return np.where(depth > 0.0, -depth, gap)


# m, how far off by rounding the distances computed here may be: two fingertips on contacts 2 r apart
# along one face (just touching) come out ~1e-17 m either side of 0; a clearance of 0 admits them
DISTANCE_ROUNDING = 1e-9


def fingers_clear(distance, clearance: float):
    """Whether the signed distances `distance` (m) keep `clearance` m, up to DISTANCE_ROUNDING."""
    return np.asarray(distance) >= clearance - DISTANCE_ROUNDING


@dataclass(frozen=True)
class FingerShapes:
    """One finger's collision shapes at K configurations, in W."""

    links: tuple[np.ndarray, ...]  # each (K, 4, 2): the corners of a link box (links without one left out)
    tip: np.ndarray  # (K, 2) m, the fingertip sphere's centre
    radius: float  # m, the fingertip sphere's radius


def finger_shapes(finger, q, tip_radius: float) -> FingerShapes:
    """The shapes of `finger` (a FingerGeometry) at its joint angles q (K, 2)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    a1, a12 = finger.angles(q)
    frames = ((np.broadcast_to(finger.p_W_base, (len(q), 2)), a1), (finger.elbow(q), a12))
    links = tuple(box.corners(p, angle) for box, (p, angle) in zip(finger.link_boxes, frames) if box is not None)
    return FingerShapes(links=links, tip=finger.fingertip(q), radius=tip_radius)


def shapes_distance(a: FingerShapes, b: FingerShapes) -> np.ndarray:
    """(K,) m, the least signed distance between any shape of finger a and any of finger b."""
    d = np.linalg.norm(a.tip - b.tip, axis=-1) - a.radius - b.radius
    for box in b.links:
        d = np.minimum(d, point_polygon_distance(a.tip, box) - a.radius)
    for box in a.links:
        d = np.minimum(d, point_polygon_distance(b.tip, box) - b.radius)
        for other in b.links:
            d = np.minimum(d, polygon_distance(box, other))
    return d


def pair_distances(fingers, q, tip_radius: float, pairs=None) -> dict[tuple[int, int], np.ndarray]:
    """{(i, j): (K,) m} the signed distance between fingers i < j at joint angles q (K, 2F,
    finger-major), for each pair of `pairs` (default: all), every pair in one vectorized pass per
    kind of shape pair (the search asks at every node it visits)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    pairs = list(itertools.combinations(range(len(fingers)), 2)) if pairs is None else list(pairs)
    used = sorted({i for pair in pairs for i in pair})  # only the fingers asked about: the shapes cost most
    shapes = {i: finger_shapes(fingers[i], q[:, 2 * i : 2 * i + 2], tip_radius) for i in used}
    return shapes_pair_distances(shapes, pairs, tip_radius)


def shapes_pair_distances(
    shapes: dict[int, FingerShapes], pairs, tip_radius: float
) -> dict[tuple[int, int], np.ndarray]:
    """pair_distances of fingers whose shapes (at the same K configurations) are given, {finger: FingerShapes}
    (the search keeps each finger's at each of its contacts: a node's siblings share three of them)."""
    pairs = list(pairs)
    if not pairs:
        return {}
    used = sorted({i for pair in pairs for i in pair})
    shapes, index = [shapes[i] for i in used], {finger: n for n, finger in enumerate(used)}
    if len({len(s.links) for s in shapes}) > 1:  # fingers boxed differently: pair by pair
        return {(i, j): shapes_distance(shapes[index[i]], shapes[index[j]]) for i, j in pairs}
    a, b = (np.array([index[i] for i in side]) for side in zip(*pairs))
    tips = np.stack([s.tip for s in shapes], axis=1)  # (K, F', 2)
    links = [np.stack([s.links[n] for s in shapes], axis=1) for n in range(len(shapes[0].links))]  # (K, F', 4, 2)
    d = np.linalg.norm(tips[:, a] - tips[:, b], axis=-1) - 2 * tip_radius  # (K, P)
    if links:  # each kind of shape pair in one call, stacked on a leading axis (the calls' overhead dominates)
        points = np.stack([tips[:, a]] * len(links) + [tips[:, b]] * len(links))  # (2L, K, P, 2)
        boxes = np.stack([box[:, b] for box in links] + [box[:, a] for box in links])  # (2L, K, P, 4, 2)
        d = np.minimum(d, point_polygon_distance(points, boxes).min(axis=0) - tip_radius)
        first, second = zip(*itertools.product(links, repeat=2))
        boxes_a, boxes_b = np.stack([box[:, a] for box in first]), np.stack([box[:, b] for box in second])
        d = np.minimum(d, polygon_distance(boxes_a, boxes_b).min(axis=0))
    return {pair: d[:, n] for n, pair in enumerate(pairs)}


def _to_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) m, the distance of points p to segments a b (all (..., 2), broadcast)."""
    e, rel = b - a, p - a
    t = np.clip(np.sum(rel * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
    off = rel - t[..., None] * e
    return np.hypot(off[..., 0], off[..., 1])


def _between_segments(a0, a1, b0, b1) -> np.ndarray:
    """(...) m, the distance between segments a0 a1 and b0 b1 (all (..., 2), broadcast): 0 where
    they cross, else the least distance of an end of either to the other. The four end-to-segment
    distances and the four sides (of an end, to the other's line) share their differences, all
    in one stack (the calls' overhead dominates at the search's sizes)."""
    ends = np.stack(np.broadcast_arrays(a0, a1, b0, b1))  # (4, ..., 2)
    start = ends[[2, 2, 0, 0]]  # a0 and a1 against segment b, b0 and b1 against segment a
    e, rel = ends[[3, 3, 1, 1]] - start, ends - start
    side = e[..., 0] * rel[..., 1] - e[..., 1] * rel[..., 0]  # the sign of each end's side of the other's line
    t = np.clip(np.sum(rel * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
    off = rel - t[..., None] * e
    crossing = (side[0] * side[1] < 0) & (side[2] * side[3] < 0)
    return np.where(crossing, 0.0, np.hypot(off[..., 0], off[..., 1]).min(axis=0))


def pair_lower_bounds(fingers, q, tip_radius: float, pairs) -> dict[tuple[int, int], np.ndarray]:
    """FingerCapsules(fingers, tip_radius).lower_bounds(q, pairs), the capsules built for this call."""
    return FingerCapsules.of(fingers, tip_radius).lower_bounds(q, pairs)


@dataclass(frozen=True)
class FingerCapsules:
    """The fingers' shapes with each link box replaced by the capsule that contains it (its long axis
    between the middles of its ends, radius its half width, as CITO's finger rows do), as arrays over
    the fingers: built once (FingerCapsules.of), then `lower_bounds` costs a few dozen array operations
    for all fingers and samples together (the search tests every move's path with it)."""

    fingers: tuple  # the FingerGeometry of each finger
    tip_radius: float  # m
    base: np.ndarray  # (F, 2) m, p_W of joint 1
    psi: np.ndarray  # (F,) rad
    l1: np.ndarray  # (F,) m
    l2: np.ndarray  # (F,) m
    links: tuple[
        int, ...
    ]  # the links with a box (0: link 1 in joint 1's frame, 1: link 2 in joint 2's), alike on every finger
    axis_J: np.ndarray  # (F, len(links), 2, 2) m, each capsule's axis ends in its joint's frame J
    width: np.ndarray  # (F, len(links)) m, each capsule's radius
    uniform: bool  # every finger has a box on the same links (else lower_bounds gives pair_distances')

    @staticmethod
    def of(fingers, tip_radius: float) -> FingerCapsules:
        fingers = tuple(fingers)
        boxed = {tuple(n for n, box in enumerate(f.link_boxes) if box is not None) for f in fingers}
        links = min(boxed)
        axis, width = [], []
        for f in fingers:
            boxes = [f.link_boxes[n] for n in links] if len(boxed) == 1 else []
            axis.append([_capsule_axis(box) for box in boxes])
            width.append([box.half_width for box in boxes])
        return FingerCapsules(
            fingers=fingers,
            tip_radius=float(tip_radius),
            base=np.array([f.p_W_base for f in fingers], dtype=float),
            psi=np.array([f.psi for f in fingers], dtype=float),
            l1=np.array([f.l1 for f in fingers], dtype=float),
            l2=np.array([f.l2 for f in fingers], dtype=float),
            links=links if len(boxed) == 1 else (),
            axis_J=np.array(axis, dtype=float).reshape(len(fingers), -1, 2, 2),
            width=np.array(width, dtype=float).reshape(len(fingers), -1),
            uniform=len(boxed) == 1,
        )

    def lower_bounds(self, q, pairs) -> dict[tuple[int, int], np.ndarray]:
        """{(i, j): (K,) m} for each of `pairs` at joint angles q (K, 2F): where not negative, at most
        pair_distances' (to rounding, 2e-16 m), at a fraction of its cost; where negative, some
        shapes' capsules overlap and only the sign means anything. Fingers boxed differently get
        pair_distances' own."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        pairs = list(pairs)
        if not pairs or not self.uniform:
            return pair_distances(self.fingers, q, self.tip_radius, pairs)
        a, b = (np.array(side) for side in zip(*pairs))
        a1 = self.psi + q[:, 0::2]  # (K, F) absolute angles of link 1, then link 2
        angles = np.stack([a1, a1 + q[:, 1::2]], axis=-1)  # (K, F, 2)
        c, s = np.cos(angles), np.sin(angles)
        elbow = self.base + self.l1[:, None] * np.stack([c[..., 0], s[..., 0]], axis=-1)  # (K, F, 2)
        tips = elbow + self.l2[:, None] * np.stack([c[..., 1], s[..., 1]], axis=-1)
        gap = tips[:, a] - tips[:, b]
        d = np.hypot(gap[..., 0], gap[..., 1]) - 2 * self.tip_radius  # (K, P)
        if not self.links:
            return {pair: d[:, n] for n, pair in enumerate(pairs)}
        link = np.array(self.links)
        origin = np.stack([np.broadcast_to(self.base, elbow.shape), elbow], axis=2)[:, :, link]  # (K, F, L, 2)
        c, s = c[:, :, link, None], s[:, :, link, None]  # (K, F, L, 1): over the axis' two ends
        ax, ay = self.axis_J[..., 0], self.axis_J[..., 1]  # (F, L, 2)
        ends = origin[..., None, :] + np.stack([c * ax - s * ay, s * ax + c * ay], axis=-1)  # (K, F, L, 2, 2)
        start, end = ends[..., 0, :], ends[..., 1, :]
        # each fingertip against the other finger's capsules, both ways in one call
        points = np.concatenate([tips[:, a], tips[:, b]], axis=1)[:, :, None]  # (K, 2P, 1, 2)
        other = np.concatenate([b, a])
        gap = _to_segments(points, start[:, other], end[:, other]) - self.width[other]  # (K, 2P, L)
        tip_gap = gap.min(axis=-1) - self.tip_radius
        d = np.minimum(d, np.minimum(tip_gap[:, : len(pairs)], tip_gap[:, len(pairs) :]))
        links = _between_segments(start[:, a, :, None], end[:, a, :, None], start[:, b, None], end[:, b, None])
        widths = self.width[a][:, :, None] + self.width[b][:, None, :]  # (P, L, L)
        d = np.minimum(d, (links - widths).min(axis=(-2, -1)))
        return {pair: d[:, n] for n, pair in enumerate(pairs)}


def _capsule_axis(box) -> list[list[float]]:
    """The ends of a LinkRectangle's capsule axis in its joint's frame: the middles of its two ends."""
    c, s = np.cos(box.angle_JG), np.sin(box.angle_JG)
    return [[box.p_JG[0] + c * x, box.p_JG[1] + s * x] for x in (box.half_length, -box.half_length)]


def sweep_bound(finger, q_from, q_to, tip_radius: float) -> float:
    """m, how far any point of `finger` (its links and fingertip sphere) moves at most on the straight
    joint-space path from q_from to q_to (2,): joint 1 turns points within l1 + l2 + r of its axis,
    joint 2 those within l2 + r of its own."""
    dq = np.abs(np.subtract(q_to, q_from))
    return float(dq[0] * (finger.l1 + finger.l2 + tip_radius) + dq[1] * (finger.l2 + tip_radius))


@dataclass(frozen=True)
class ClosestFingers:
    """The closest two fingers come over K configurations."""

    distance: float  # m, signed: minus the deepest overlap (inf with fewer than two fingers)
    knot: int  # the configuration where (-1: none)
    fingers: tuple[int, ...]  # the two fingers, (i, j) with i < j (() : none)


def closest_fingers(fingers, q, tip_radius: float) -> ClosestFingers:
    """Where over the configurations q (K, 2F) two fingers come closest, and how close."""
    best = ClosestFingers(float("inf"), -1, ())
    for pair, d in pair_distances(fingers, q, tip_radius).items():
        k = int(np.argmin(d))
        if d[k] < best.distance:
            best = ClosestFingers(float(d[k]), k, pair)
    return best


def interpolate_joints(q, samples: int) -> np.ndarray:
    """(samples (K - 1) + 1, n): the straight joint-space path through the rows of q (K, n),
    `samples` steps between consecutive rows (their ends included once)."""
    q = np.asarray(q, dtype=float)
    t = np.linspace(0.0, 1.0, samples + 1)[:-1, None]
    inner = (q[:-1, None, :] + t[None] * (q[1:] - q[:-1])[:, None, :]).reshape(-1, q.shape[1])
    return np.vstack([inner, q[-1:]])
