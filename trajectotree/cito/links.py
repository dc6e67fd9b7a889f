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

Each row depends on the knot's object pose and the finger's two joints only, so each knot's
binding holds just those (x, q: LINK_SIZE variables; IPOPT's AutoDiff inputs are 11 wide, not
the knot's 53): d p_WL / d q_j = K (p_WL - p_WJ_j) for the joints j at or before the link
(K: +90 degrees). `evaluate` is elementwise (no matmul), so a batch of knots and one knot
give the same bits, as program._KnotCache expects of the rows it serves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

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


# A link block's variables (its binding's, per knot): the object's pose x (3), then the joints q (8).
LINK_SIZE = 3 + 2 * NUM_FINGERS
COL_P, COL_TH = (0, 1), 2
COL_Q = 3 + 2 * np.arange(NUM_FINGERS)[:, None] + np.arange(2)     # (4, 2)


class LinkRows:
    """The link rows of K knots (values phi(p_BL) - w, finger-major, P per finger) on their
    (x, q) blocks, with the interface program._KnotCache and _KnotConstraint use: evaluate,
    knot, values_one, num_rows."""

    def __init__(self, body, num_knots: int):
        self.body = body
        self.points = LinkPoints.from_boxes(body.link_boxes)
        self.num_rows = np.full(num_knots, NUM_FINGERS * self.points.per_finger)
        f = body.hand.fingers
        self._p_W_base, self._psi, self._l1 = f.p_W_base, f.psi, f.l1      # (4, 2), (4,), (4,)
        # per face (n_x, n_y, offset) as floats: the sums over faces run elementwise, left to right
        self._faces = [(float(n[0]), float(n[1]), float(h)) for n, h in zip(body.normals, body.offsets)]
        pts = self.points
        self._scalars = tuple(                  # values_one's constants as Python floats
            (float(f.psi[i]), float(f.l1[i]), float(f.p_W_base[i, 0]), float(f.p_W_base[i, 1]),
             tuple((bool(link), float(p[0]), float(p[1]), float(w))
                   for link, p, w in zip(pts.link, pts.p_JL[i], pts.half_width[i])))
            for i in range(NUM_FINGERS))

    def knot(self, k: int) -> "LinkRows":
        return LinkRows(self.body, 1)

    @staticmethod
    def block(x, q) -> np.ndarray:
        """A knot's (x, q) block (LINK_SIZE,) from its pose and joint angles."""
        return np.concatenate([np.asarray(x, dtype=float), np.asarray(q, dtype=float)])

    def bounds(self, clearance: float, fixed_states=()):
        """(lower, upper) of one knot's rows: each point's gap >= clearance (m), but no more than
        the point has at any of `fixed_states` ((x, q) pairs: the program's fixed end knots, the
        search's nodes). The search clears the link boxes by its exact test, which may leave a
        point within the clearance, or (beyond an object corner, where the smooth distance is
        below the exact one) below 0: the knots next to the node could not get out in time."""
        lower = np.full(int(self.num_rows[0]), float(clearance))
        for x, q in fixed_states:
            lower = np.minimum(lower, self.values_one(self.block(x, q)))
        return lower, np.full(lower.size, np.inf)

    def sparsity(self) -> list[tuple[int, int]]:
        """(row, col) entries of one knot's Jacobian that can be nonzero: the object's pose,
        the finger's joint 1, and its joint 2 for points on link 2."""
        out = []
        for i in range(NUM_FINGERS):
            for j, link in enumerate(self.points.link):
                cols = [*COL_P, COL_TH, int(COL_Q[i, 0])] + ([int(COL_Q[i, 1])] if link else [])
                out += [(i * self.points.per_finger + j, c) for c in cols]
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
        """(values (K, R), Jacobians (K, R, LINK_SIZE) or None) at the (x, q) blocks Z (K, LINK_SIZE)."""
        pts = self.points
        nK, P = Z.shape[0], pts.per_finger
        q = Z[:, COL_Q]                                                     # (K, 4, 2)
        a1 = self._psi + q[..., 0]                                          # (K, 4)
        a12 = a1 + q[..., 1]
        c1, s1, c12, s12 = np.cos(a1), np.sin(a1), np.cos(a12), np.sin(a12)
        elbow_x = self._p_W_base[:, 0] + self._l1 * c1
        elbow_y = self._p_W_base[:, 1] + self._l1 * s1
        on2 = pts.link.astype(bool)                                         # (P,)
        # the frame J of each point's link: origin and angle (K, 4, P)
        ox = np.where(on2, elbow_x[..., None], self._p_W_base[:, 0, None])
        oy = np.where(on2, elbow_y[..., None], self._p_W_base[:, 1, None])
        c = np.where(on2, c12[..., None], c1[..., None])
        s = np.where(on2, s12[..., None], s1[..., None])
        lx, ly = pts.p_JL[..., 0], pts.p_JL[..., 1]                         # (4, P)
        wx, wy = ox + (c * lx - s * ly), oy + (s * lx + c * ly)             # p_WL
        rx, ry = wx - Z[:, 0, None, None], wy - Z[:, 1, None, None]
        th = Z[:, COL_TH, None, None]
        ct, st = np.cos(th), np.sin(th)
        bx, by = ct * rx + st * ry, -st * rx + ct * ry                      # p_BL = R^T (p_WL - p)
        phi, gx, gy = self._smooth_distance(bx, by)
        val = (phi - pts.half_width).reshape(nK, -1)
        if not with_jacobian:
            return val, None
        gwx, gwy = ct * gx - st * gy, st * gx + ct * gy                     # R g = d phi / d p_WL
        jac = np.zeros((nK, NUM_FINGERS, P, LINK_SIZE))
        jac[..., COL_P[0]], jac[..., COL_P[1]] = -gwx, -gwy
        jac[..., COL_TH] = gwx * ry - gwy * rx                              # d p_BL / d theta = -R^T K (p_WL - p)
        # joint 1 turns every point about the base, joint 2 the link-2 points about the elbow
        d_q1 = gwy * (wx - self._p_W_base[:, 0, None]) - gwx * (wy - self._p_W_base[:, 1, None])
        d_q2 = np.where(on2, gwy * (wx - elbow_x[..., None]) - gwx * (wy - elbow_y[..., None]), 0.0)
        fingers = np.arange(NUM_FINGERS)
        jac[:, fingers, :, COL_Q[:, 0]] = d_q1.transpose(1, 0, 2)
        jac[:, fingers, :, COL_Q[:, 1]] = d_q2.transpose(1, 0, 2)
        return val, jac.reshape(nK, NUM_FINGERS * P, LINK_SIZE)

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows at one block z (LINK_SIZE,): `evaluate`'s arithmetic in Python floats, 2.5x
        faster for one knot (IPOPT asks for values at each trial point knot by knot); math's
        exp and log may differ from numpy's in the last bit (tests compare them to 1e-12)."""
        px, py, th, *q = z.tolist()
        ct, st = math.cos(th), math.sin(th)
        k, faces = self.body.sharpness, self._faces
        out = []
        for i, (psi, l1, base_x, base_y, points) in enumerate(self._scalars):
            a1 = psi + q[2 * i]
            a12 = a1 + q[2 * i + 1]
            c1, s1, c12, s12 = math.cos(a1), math.sin(a1), math.cos(a12), math.sin(a12)
            elbow_x, elbow_y = base_x + l1 * c1, base_y + l1 * s1
            for on2, lx, ly, w in points:
                if on2:
                    wx, wy = elbow_x + (c12 * lx - s12 * ly), elbow_y + (s12 * lx + c12 * ly)
                else:
                    wx, wy = base_x + (c1 * lx - s1 * ly), base_y + (s1 * lx + c1 * ly)
                rx, ry = wx - px, wy - py
                bx, by = ct * rx + st * ry, -st * rx + ct * ry
                d = [nx * bx + ny * by - h for nx, ny, h in faces]
                dmax = max(d)
                total = 0.0
                for dj in d:
                    total += math.exp(k * (dj - dmax))
                out.append(dmax + math.log(total) / k - w)
        return np.array(out)
