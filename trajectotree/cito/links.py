"""Link non-penetration rows: points on each finger's link collision boxes keep out of the object.

The knot rows (knot.py) let only the fingertip spheres see the object, so a finger's links
could pass through it between the search's nodes (43 of 60 keyframes plans of the seed-0
goals did, up to 24 mm deep). Here, at every knot whose pose or joints are free, points
p_L on the centreline of each link's collision box (SceneGraph's, `FingerGeometry.link_boxes`)
must satisfy

    phi(p_BL) - w >= link_clearance,   p_BL = R^T (p_WL - p),

phi the same log-sum-exp object distance as the fingertip rows (contact.py) and w the box's
half width: a disc of radius w + clearance around each point stays out of the object.
The points (LINK_FRACTIONS, of each box's length from its joint end): link 1 at its middle
and its far end (the elbow, also link 2's joint end), link 2 at 1/4, 1/2 and 3/4. In the 60
plans every inside point of link 1 lay within its last 17 % (elbow side), those of link 2
anywhere along it; link 2's far end (85 mm from the elbow) is within 15 mm of the fingertip
sphere's centre, which keeps r = 10 mm (> w = 4.8 mm) off the object already. Between the
points an object corner can still reach into a link's side (the rows see the side only at
the points); the measured depths are in README's "Trajectory optimization".

Each row depends on the knot's object pose and the finger's two joints only:
d p_WL / d q_j = K (p_WL - p_WJ_j) for the joints j at or before the link (K: +90 degrees).
The arithmetic is elementwise (no matmul) so a batch of knots and one knot give the same
bits, as program._KnotCache requires of the rows it serves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectotree.cito.layout import COL_P, COL_Q, COL_TH
from trajectotree.cito.variables import KNOT_SIZE, SLICES
from trajectotree.scene import NUM_FINGERS

# Per link (1, 2), the sampled fractions of its collision box's length from the joint end.
LINK_FRACTIONS = ((0.5, 1.0), (0.25, 0.5, 0.75))


def _centreline(box, fractions) -> np.ndarray:
    """(n, 2) m, points p_JL on a LinkRectangle's centreline in its joint frame J, at `fractions`
    (n,) of its length from the end nearer the joint (0) to the far end (1)."""
    t = (2.0 * np.asarray(fractions, dtype=float) - 1.0) * box.half_length
    return box.p_JG + t[:, None] * np.array([np.cos(box.angle_JG), np.sin(box.angle_JG)])


@dataclass(frozen=True)
class LinkPoints:
    """The sampled points of the four fingers, P per finger (finger-major rows i P + j)."""

    link: np.ndarray         # (P,) int, 0: on link 1 (moved by joint 1), 1: on link 2 (both joints)
    p_JL: np.ndarray         # (4, P, 2) m, point in the frame of the joint that moves its link
    half_width: np.ndarray   # (4, P) m, half width of that link's collision box

    @staticmethod
    def from_boxes(link_boxes) -> "LinkPoints":
        """From each finger's `FingerGeometry.link_boxes` (link 1's and link 2's LinkRectangle)."""
        link = np.concatenate([np.full(len(f), j) for j, f in enumerate(LINK_FRACTIONS)])
        p_JL = np.array([np.concatenate([_centreline(box, f) for box, f in zip(boxes, LINK_FRACTIONS)])
                         for boxes in link_boxes])
        half_width = np.array([[boxes[j].half_width for j in link] for boxes in link_boxes])
        return LinkPoints(link=link, p_JL=p_JL, half_width=half_width)

    @property
    def per_finger(self) -> int:
        return len(self.link)


class LinkRows:
    """The link rows of K knots (values phi(p_BL) - w, one per finger and point), with the
    interface program._KnotCache and _KnotConstraint use: evaluate, knot, values_one, num_rows."""

    def __init__(self, body, num_knots: int):
        self.body = body
        self.points = LinkPoints.from_boxes(body.link_boxes)
        self.num_rows = np.full(num_knots, NUM_FINGERS * self.points.per_finger)
        f = body.hand.fingers
        self._p_W_base, self._psi, self._l1 = f.p_W_base, f.psi, f.l1      # (4, 2), (4,), (4,)
        # per face (n_x, n_y, offset) as floats: the sums over faces run elementwise, left to right
        self._faces = [(float(n[0]), float(n[1]), float(h)) for n, h in zip(body.normals, body.offsets)]

    def knot(self, k: int) -> "LinkRows":
        return LinkRows(self.body, 1)

    def bounds(self, clearance: float, fixed_states=()):
        """(lower, upper) of one knot's rows: each point's gap >= clearance (m), but no more than
        the point has at any of `fixed_states` ((x, q) pairs: the program's fixed end knots, the
        search's nodes). The search clears the link boxes by its exact test, which may leave a
        point within the clearance, or (beyond an object corner, where the smooth distance is
        below the exact one) below 0: the knots next to the node could not get out in time."""
        lower = np.full(int(self.num_rows[0]), float(clearance))
        for x, q in fixed_states:
            z = np.zeros(KNOT_SIZE)
            z[SLICES["x"]], z[SLICES["q"]] = x, q
            lower = np.minimum(lower, self.values_one(z))
        return lower, np.full(lower.size, np.inf)

    def sparsity(self) -> list[tuple[int, int]]:
        """(row, col) entries of one knot's Jacobian that can be nonzero: the object's pose,
        the finger's joint 1, and its joint 2 for points on link 2."""
        out = []
        for i in range(NUM_FINGERS):
            for j, link in enumerate(self.points.link):
                row = i * self.points.per_finger + j
                cols = [COL_P.start, COL_P.start + 1, COL_TH, int(COL_Q[i, 0])] + ([int(COL_Q[i, 1])] if link else [])
                out += [(row, c) for c in sorted(cols)]
        return out

    def _smooth_distance(self, bx: np.ndarray, by: np.ndarray):
        """(phi, g_x, g_y) of contact.smooth_distance at points (bx, by) in B, elementwise."""
        k = self.body.sharpness
        d = [nx * bx + ny * by - h for nx, ny, h in self._faces]
        dmax = d[0]
        for dj in d[1:]:
            dmax = np.maximum(dmax, dj)
        total = gx = gy = 0.0
        for dj, (nx, ny, _) in zip(d, self._faces):
            e = np.exp(k * (dj - dmax))
            total = total + e
            gx = gx + e * nx
            gy = gy + e * ny
        return dmax + np.log(total) / k, gx / total, gy / total

    def evaluate(self, Z: np.ndarray, with_jacobian: bool):
        """(values (K, R), Jacobians (K, R, KNOT_SIZE) or None) at knots Z (K, KNOT_SIZE)."""
        pts = self.points
        nK, P = Z.shape[0], pts.per_finger
        th = Z[:, COL_TH][:, None, None]
        q = Z[:, SLICES["q"]].reshape(nK, NUM_FINGERS, 2)
        a1 = self._psi + q[..., 0]                                         # (K, 4)
        a12 = a1 + q[..., 1]
        c1, s1, c12, s12 = np.cos(a1), np.sin(a1), np.cos(a12), np.sin(a12)
        elbow_x = self._p_W_base[:, 0] + self._l1 * c1                     # (K, 4)
        elbow_y = self._p_W_base[:, 1] + self._l1 * s1
        on2 = pts.link.astype(bool)                                        # (P,)
        # joint frame J of each point's link: origin and angle
        ox = np.where(on2, elbow_x[..., None], self._p_W_base[:, 0, None])   # (K, 4, P)
        oy = np.where(on2, elbow_y[..., None], self._p_W_base[:, 1, None])
        c = np.where(on2, c12[..., None], c1[..., None])
        s = np.where(on2, s12[..., None], s1[..., None])
        lx, ly = pts.p_JL[..., 0], pts.p_JL[..., 1]                        # (4, P)
        wx, wy = ox + (c * lx - s * ly), oy + (s * lx + c * ly)            # p_WL
        rx, ry = wx - Z[:, COL_P.start, None, None], wy - Z[:, COL_P.start + 1, None, None]
        ct, st = np.cos(th), np.sin(th)
        bx, by = ct * rx + st * ry, -st * rx + ct * ry                     # p_BL = R^T (p_WL - p)
        phi, gx, gy = self._smooth_distance(bx, by)
        val = (phi - pts.half_width).reshape(nK, -1)
        if not with_jacobian:
            return val, None
        gwx, gwy = ct * gx - st * gy, st * gx + ct * gy                    # R g: d phi / d p_WL
        jac = np.zeros((nK, NUM_FINGERS, P, KNOT_SIZE))
        jac[..., COL_P.start] = -gwx
        jac[..., COL_P.start + 1] = -gwy
        jac[..., COL_TH] = gwx * ry - gwy * rx                             # d p_BL / d theta = -R^T K (p_WL - p)
        fingers = np.arange(NUM_FINGERS)
        # joint 1 turns every point about the base; joint 2 turns link-2 points about the elbow
        d_q1 = -gwx * (wy - self._p_W_base[:, 1, None]) + gwy * (wx - self._p_W_base[:, 0, None])
        d_q2 = np.where(on2, -gwx * (wy - elbow_y[..., None]) + gwy * (wx - elbow_x[..., None]), 0.0)
        jac[:, fingers, :, COL_Q[:, 0]] = d_q1.transpose(1, 0, 2)
        jac[:, fingers, :, COL_Q[:, 1]] = d_q2.transpose(1, 0, 2)
        return val, jac.reshape(nK, NUM_FINGERS * P, KNOT_SIZE)

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows of one knot at z (KNOT_SIZE,): the batch's numbers."""
        return self.evaluate(z[None], False)[0][0]
