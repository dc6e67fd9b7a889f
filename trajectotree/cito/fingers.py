"""Finger-finger rows: the fingers keep apart in the trajectory, as the link rows keep them out of the object.

The search keeps two fingers search.finger_clearance apart at its nodes and on the straight
joint-space path between them (exact planar test, trajectotree.scene.finger_clearance); between
the nodes the trajectory leaves that path (the switching finger lifts off and swings). Here each
finger is a chain of capsules, smooth to differentiate and conservative (each contains its link's
collision box; the fingertip sphere is a disc of radius r at link 2's end):

    link 1: segment base -> elbow, radius w1;  link 2: segment elbow -> fingertip centre, radius w2,

and, for each pair of fingers (a, b) a row per point P of a, {elbow (radius max(w1, w2)), fingertip
centre (radius r)}, and capsule S of b, both ways, plus one between the two fingertip centres:

    |P - S(t*)| - r_P - r_S >= c,   |p_aF - p_bF| - 2 r >= c,

S(t*) the point of S's segment nearest P (t* clamped to [0, 1]), c = cito.link_clearance. A
distance to a segment is C1 wherever it is positive, so the rows are smooth where they hold.
Two segments that come to cross first meet at one's end (an elbow or a fingertip: the points
above; the bases are fixed and far apart). The rows depend on the two fingers' joints only: a
knot's block is q (2F); d P / d q_j = K (P - p_WJ_j) for the joints j at or before P (K: +90 deg).

Which pairs get rows (`near_pairs`): those that come within NEAR_MARGIN of each other on the
straight joint-space path between the program's nodes (exact test, cheap), since most pairs of a
segment stay far apart (the planar hand's opposite fingers always do).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from trajectotree.scene.finger_clearance import interpolate_joints, pair_distances

# m, a pair of fingers gets rows in a program when it comes within this of each other on the straight
# joint-space path between the program's nodes: twice the fingertip sphere's 10 mm lift off the object
# (cito.switch_clearance), by which the trajectory's switching finger leaves that path
NEAR_MARGIN = 0.02
PATH_SAMPLES = 20  # samples per segment of that path (a joint turns at most 1.83 rad in a segment: 0.09 rad each)
BASE, ELBOW, TIP = 0, 1, 2  # a finger's nodes


def near_pairs(fingers, q_nodes, tip_radius: float, margin: float = NEAR_MARGIN) -> tuple[tuple[int, int], ...]:
    """The pairs (i, j), i < j, of `fingers` within `margin` m of each other somewhere on the straight
    joint-space path through the joint angles q_nodes (N, 2F) of consecutive search nodes."""
    path = interpolate_joints(np.asarray(q_nodes, dtype=float), PATH_SAMPLES)
    distances = pair_distances(fingers, path, tip_radius)
    return tuple(pair for pair, d in distances.items() if d.min() < margin)


@dataclass(frozen=True)
class _RowTable:
    """Per row: the point (finger, node, radius) and the segment (finger, start node, end node, radius)."""

    point_finger: np.ndarray  # (R,) int
    point_node: np.ndarray  # (R,) int: ELBOW or TIP
    segment_finger: np.ndarray  # (R,) int
    segment_start: np.ndarray  # (R,) int: BASE, ELBOW or TIP (TIP to TIP: the fingertip centre itself)
    segment_end: np.ndarray  # (R,) int
    radii: np.ndarray  # (R,) m, r_P + r_S


def _row_table(link_boxes, tip_radius: float, pairs) -> _RowTable:
    rows = []
    for i, j in pairs:
        for a, b in ((i, j), (j, i)):
            widths = [box.half_width for box in link_boxes[a] if box is not None]
            points = ([(ELBOW, max(widths))] if widths else []) + [(TIP, tip_radius)]
            segments = [
                (start, end, box.half_width)
                for (start, end), box in zip(((BASE, ELBOW), (ELBOW, TIP)), link_boxes[b])
                if box is not None
            ]
            rows += [
                (a, node, b, start, end, r + w) for (node, r), (start, end, w) in itertools.product(points, segments)
            ]
        rows.append((i, TIP, j, TIP, TIP, 2 * tip_radius))
    columns = list(zip(*rows)) if rows else [()] * 6
    return _RowTable(*(np.array(c, dtype=int) for c in columns[:5]), radii=np.array(columns[5], dtype=float))


def _cross(u, v):
    """u_x v_y - u_y v_x, so that u . (K v) = -cross(u, v)."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


class FingerRows:
    """The finger-finger rows of K knots on their joint blocks q (2F), for the pairs of fingers given,
    with the interface of program._KnotCache and _KnotConstraint: evaluate, knot, values_one, num_rows."""

    def __init__(self, body, pairs, num_knots: int):
        self.pairs = tuple(pairs)
        f = body.hand.fingers
        self._p_W_base, self._psi, self._l1, self._l2 = f.p_W_base, f.psi, f.l1, f.l2  # (F, 2), (F,), (F,), (F,)
        self.num_fingers = len(body.fingers)
        self.block_size = 2 * self.num_fingers
        self._rows = _row_table(body.link_boxes, body.radius, self.pairs)
        self.num_rows = np.full(num_knots, len(self._rows.radii))

    def knot(self, k: int) -> FingerRows:
        """Knot k's rows alone: these, as no row depends on the knot (evaluate takes any batch size)."""
        return self

    def bounds(self, clearance: float, fixed_q=()):
        """(lower, upper) of one knot's rows: each row >= clearance (m), but no more than it has at any of
        `fixed_q` (2F joint angles: the program's fixed end knots, the search's nodes, which the search
        kept apart by its exact test, where these capsules may sit closer)."""
        lower = np.full(int(self.num_rows[0]), float(clearance))
        for q in fixed_q:
            lower = np.minimum(lower, self.values_one(np.asarray(q, dtype=float)))
        return lower, np.full(lower.size, np.inf)

    def sparsity(self) -> list[tuple[int, int]]:
        """(row, col) entries of one knot's Jacobian that can be nonzero: both fingers' joints."""
        t = self._rows
        return [
            (r, 2 * finger + j)
            for r, (a, b) in enumerate(zip(t.point_finger.tolist(), t.segment_finger.tolist()))
            for finger in (a, b)
            for j in range(2)
        ]

    def _nodes(self, Z: np.ndarray):
        """Each finger's base, elbow and fingertip centre in W, (K, F, 3, 2), from the blocks Z (K, 2F)."""
        q = Z.reshape(len(Z), self.num_fingers, 2)
        a1 = self._psi + q[..., 0]
        a12 = a1 + q[..., 1]
        base = np.broadcast_to(self._p_W_base, q.shape)
        elbow = base + self._l1[:, None] * np.stack([np.cos(a1), np.sin(a1)], axis=-1)
        tip = elbow + self._l2[:, None] * np.stack([np.cos(a12), np.sin(a12)], axis=-1)
        return np.stack([base, elbow, tip], axis=2)

    def evaluate(self, Z: np.ndarray, with_jacobian: bool):
        """(values (K, R), Jacobians (K, R, 2F) or None) at the joint blocks Z (K, 2F)."""
        t, nodes = self._rows, self._nodes(np.asarray(Z, dtype=float))
        P = nodes[:, t.point_finger, t.point_node]  # (K, R, 2)
        A, B = nodes[:, t.segment_finger, t.segment_start], nodes[:, t.segment_finger, t.segment_end]
        e = B - A
        ee = e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1]
        d = P - A
        dot = d[..., 0] * e[..., 0] + d[..., 1] * e[..., 1]
        s = np.clip(np.divide(dot, ee, out=np.zeros_like(dot), where=ee > 0.0), 0.0, 1.0)
        gap = P - (A + s[..., None] * e)
        dist = np.sqrt(gap[..., 0] * gap[..., 0] + gap[..., 1] * gap[..., 1])
        val = dist - t.radii
        if not with_jacobian:
            return val, None
        u = gap / np.maximum(dist, 1e-12)[..., None]  # d dist / d P; -(1 - s) u and -s u on A and B
        rows = np.arange(len(t.radii))
        jac = np.zeros((len(Z), len(rows), self.block_size))

        def moved(x, finger, node, joint):
            """u . d x / d q_joint of finger's node x (K, R, 2): u . K (x - p_WJ) = -cross(u, x - p_WJ)."""
            pivot = nodes[:, finger, joint]
            return np.where(node > joint, -_cross(u, x - pivot), 0.0)

        for joint in range(2):  # joint 1 turns about the base (node 0), joint 2 about the elbow (node 1)
            jac[:, rows, 2 * t.point_finger + joint] += moved(P, t.point_finger, t.point_node, joint)
            jac[:, rows, 2 * t.segment_finger + joint] -= (1.0 - s) * moved(
                A, t.segment_finger, t.segment_start, joint
            ) + s * moved(B, t.segment_finger, t.segment_end, joint)
        return val, jac

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows at one block z (2F,)."""
        return self.evaluate(np.asarray(z, dtype=float)[None], False)[0][0]
