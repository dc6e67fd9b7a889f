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
    if not pairs:
        return {}
    used = sorted({i for pair in pairs for i in pair})  # only the fingers asked about: the shapes cost most
    shapes = [finger_shapes(fingers[i], q[:, 2 * i : 2 * i + 2], tip_radius) for i in used]
    index = {finger: n for n, finger in enumerate(used)}
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
    e = b - a
    t = np.clip(np.sum((p - a) * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
    return np.linalg.norm(p - a - t[..., None] * e, axis=-1)


def _between_segments(a0, a1, b0, b1) -> np.ndarray:
    """(...) m, the distance between segments a0 a1 and b0 b1 (all (..., 2), broadcast): 0 where
    they cross, else the least distance of an end of either to the other."""

    def side(p, q, r):  # the sign of r's side of the line p q
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    ends = np.minimum(
        np.minimum(_to_segments(a0, b0, b1), _to_segments(a1, b0, b1)),
        np.minimum(_to_segments(b0, a0, a1), _to_segments(b1, a0, a1)),
    )
    crossing = (side(a0, a1, b0) * side(a0, a1, b1) < 0) & (side(b0, b1, a0) * side(b0, b1, a1) < 0)
    return np.where(crossing, 0.0, ends)


def pair_lower_bounds(fingers, q, tip_radius: float, pairs) -> dict[tuple[int, int], np.ndarray]:
    """{(i, j): (K,) m} for each of `pairs` at joint angles q (K, 2F): where not negative, at most
    pair_distances' (to rounding, 2e-16 m), at about 40 % of its cost (each link box replaced by the
    capsule that contains it, its long axis between the middles of its ends, radius its half
    width, as CITO's finger rows do); where negative, some shapes' capsules overlap and only the
    sign means anything. Fingers boxed differently get pair_distances' own."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    pairs = list(pairs)
    used = sorted({i for pair in pairs for i in pair})
    shapes = [finger_shapes(fingers[i], q[:, 2 * i : 2 * i + 2], tip_radius) for i in used]
    if not pairs or len({len(s.links) for s in shapes}) > 1:
        return pair_distances(fingers, q, tip_radius, pairs)
    index = {finger: n for n, finger in enumerate(used)}
    a, b = (np.array([index[i] for i in side]) for side in zip(*pairs))
    tips = np.stack([s.tip for s in shapes], axis=1)  # (K, F', 2)
    d = np.linalg.norm(tips[:, a] - tips[:, b], axis=-1) - 2 * tip_radius  # (K, P)
    if shapes[0].links:
        boxes = np.stack([np.stack(s.links, axis=1) for s in shapes], axis=1)  # (K, F', L, 4, 2)
        start, end = 0.5 * (boxes[..., 0, :] + boxes[..., 1, :]), 0.5 * (boxes[..., 2, :] + boxes[..., 3, :])
        width = 0.5 * np.linalg.norm(boxes[..., 1, :] - boxes[..., 0, :], axis=-1)  # (K, F', L)
        for tip, other in ((tips[:, a], b), (tips[:, b], a)):  # each fingertip against the other's links
            gap = _to_segments(tip[:, :, None], start[:, other], end[:, other]) - width[:, other]
            d = np.minimum(d, gap.min(axis=-1) - tip_radius)
        links = _between_segments(start[:, a, :, None], end[:, a, :, None], start[:, b, None], end[:, b, None])
        d = np.minimum(d, (links - width[:, a, :, None] - width[:, b, None]).min(axis=(-2, -1)))
    return {pair: d[:, n] for n, pair in enumerate(pairs)}


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
