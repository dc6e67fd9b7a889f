"""Link non-penetration rows: each finger's link collision boxes keep out of the object.

The knot rows (knot.py) let only the fingertip spheres see the object, so a finger's links
could pass through it between the search's nodes (44 of the 60 seed-0 keyframes plans did,
43 of them over 5 mm, up to 32 mm). Here, at every knot whose pose or joints are free, two
kinds of rows on the link boxes (SceneGraph's, `FingerGeometry.link_boxes`), each >= the
clearance c (CitoConfig.link_clearance):

  points:   phi(p_BL) - w >= c,   p_BL = R^T (p_WL - p), p_L on a box's centreline,
            phi the log-sum-exp object distance of the fingertip rows (contact.py), w the box's
            half width: a disc of radius w + c around each point stays out of the object;
  vertices: psi_i(p_GV) >= c for each object vertex V and finger i's link-2 box G, psi_i the
            same log-sum-exp over the box's four faces in its own frame: each object corner
            stays out of the box (exact at a face, up to log(2)/k = 0.7 mm deeper at the box's
            corners, conservative beyond them).

The points (LINK_FRACTIONS, of each box's length from its joint end): link 1 at its middle
and its far end (the elbow, also link 2's joint end), link 2 at 1/4, 1/2 and 3/4. In the 60
plans without these rows every inside point of link 1 lay within its last 17 % (elbow side),
those of link 2 anywhere along it; link 2's far end (85 mm from the elbow) is within 15 mm of
the fingertip sphere's centre, which keeps r = 10 mm (> w = 4.8 mm) off the object already.
With the points alone an object corner still reached between two points into link 2 (the
switching finger rounding a corner: 20 of the 60 plans, up to 5.5 mm): hence the vertex rows,
after which none of the 60 had a link inside the object. Link 1 has no vertex rows: its
inside points were all at the elbow, which the elbow point keeps out.

Each row depends on the knot's object pose and the finger's two joints only, so each knot's
binding holds just those (x, q: LINK_SIZE variables; IPOPT's AutoDiff inputs are 11 wide, not
the knot's 53): d p_WL / d q_j = K (p_WL - p_WJ_j) for the joints j at or before the link
(K: +90 degrees); a vertex moves by the opposite in the box's frame. `evaluate` is elementwise
(no matmul), so a batch of knots and one knot give the same bits, as program._KnotCache
expects of the rows it serves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Per link (1, 2), the sampled fractions of its collision box's length from the joint end.
LINK_FRACTIONS = ((0.5, 1.0), (0.25, 0.5, 0.75))


def _centreline(box, fractions) -> np.ndarray:
    """(n, 2) m, points p_JL on a LinkRectangle's centreline in its joint frame J, at `fractions`
    (n,) of its length from the end nearer the joint (0) to the far end (1)."""
    t = (2.0 * np.asarray(fractions, dtype=float) - 1.0) * box.half_length
    return box.p_JG + t[:, None] * np.array([np.cos(box.angle_JG), np.sin(box.angle_JG)])


@dataclass(frozen=True)
class LinkPoints:
    """The sampled points of the fingers, P per finger (finger-major rows i P + j)."""

    link: np.ndarray  # (P,) int, 0: on link 1 (moved by joint 1), 1: on link 2 (both joints)
    p_JL: np.ndarray  # (4, P, 2) m, point in the frame of the joint that moves its link
    half_width: np.ndarray  # (4, P) m, half width of that link's collision box

    @staticmethod
    def from_boxes(link_boxes) -> LinkPoints:
        """From each finger's `FingerGeometry.link_boxes` (link 1's and link 2's LinkRectangle; a
        link without a box, None on every finger, has no points: Drake's gripper's link 1)."""
        boxed = [j for j in range(len(LINK_FRACTIONS)) if link_boxes[0][j] is not None]
        if any([j for j in range(len(LINK_FRACTIONS)) if boxes[j] is not None] != boxed for boxes in link_boxes):
            raise ValueError("the link rows need the same links boxed on every finger")
        link = np.concatenate([np.full(len(LINK_FRACTIONS[j]), j) for j in boxed])
        p_JL = np.array(
            [np.concatenate([_centreline(boxes[j], LINK_FRACTIONS[j]) for j in boxed]) for boxes in link_boxes]
        )
        half_width = np.array([[boxes[j].half_width for j in link] for boxes in link_boxes])
        return LinkPoints(link=link, p_JL=p_JL, half_width=half_width)

    @property
    def per_finger(self) -> int:
        return len(self.link)


@dataclass(frozen=True)
class _Box2:
    """Each finger's link-2 collision box (LinkRectangle) as arrays (4, ...), in joint 2's frame."""

    p_JG: np.ndarray  # (4, 2) m, box centre
    angle_JG: np.ndarray  # (4,) rad
    half_length: np.ndarray  # (4,) m
    half_width: np.ndarray  # (4,) m

    @staticmethod
    def from_boxes(link_boxes) -> _Box2:
        b = [boxes[1] for boxes in link_boxes]
        return _Box2(
            p_JG=np.array([x.p_JG for x in b]),
            angle_JG=np.array([x.angle_JG for x in b]),
            half_length=np.array([x.half_length for x in b]),
            half_width=np.array([x.half_width for x in b]),
        )


@dataclass(frozen=True)
class _Kinematics:
    """A batch's angles and elbows: cos and sin of a1, a12 (K, 4) and theta (K, 1, 1), elbows in W (K, 4)."""

    c1: np.ndarray
    s1: np.ndarray
    c12: np.ndarray
    s12: np.ndarray
    ct: np.ndarray
    st: np.ndarray
    elbow_x: np.ndarray
    elbow_y: np.ndarray


def _weighted(weights: list, normals: list):
    """sum_j weights_j n_j, left to right: the log-sum-exp's gradient (x, y)."""
    gx = gy = 0.0
    for wj, (nx, ny) in zip(weights, normals):
        gx = gx + wj * nx
        gy = gy + wj * ny
    return gx, gy


# A link block's variables (its binding's, per knot): the object's pose x (3), then the joints q (2F).
COL_P, COL_TH = (0, 1), 2


def link_columns(num_fingers: int) -> tuple[int, np.ndarray]:
    """(size of a link block, (F, 2) columns of each finger's joints in it)."""
    return 3 + 2 * num_fingers, 3 + 2 * np.arange(num_fingers)[:, None] + np.arange(2)


class LinkRows:
    """The link rows of K knots on their (x, q) blocks: P point rows per finger (phi(p_BL) - w),
    then V vertex rows per finger (psi_i(p_GV)), both finger-major, with the interface
    program._KnotCache and _KnotConstraint use: evaluate, knot, values_one, num_rows. `fingers`:
    the fingers whose rows these are (None: every finger), in the same order with the others'
    left out: a segment where one finger's links come near the object needs no rows on the others'."""

    def __init__(self, body, num_knots: int, fingers: tuple[int, ...] | None = None):
        self.body = body
        self.num_fingers = len(body.fingers)
        self.link_size, self.col_q = link_columns(self.num_fingers)
        self.points = LinkPoints.from_boxes(body.link_boxes)
        self._box2 = _Box2.from_boxes(body.link_boxes)
        self._vertices = np.asarray(body.shape.vertices, dtype=float)  # (V, 2) m, in B
        kept = tuple(range(self.num_fingers)) if fingers is None else tuple(sorted(set(fingers)))
        self.fingers = kept
        P, V = self.points.per_finger, len(self._vertices)
        # the kept rows' indices among every finger's (point rows, then vertex rows, finger-major)
        self._kept = np.concatenate(
            [np.arange(i * P, (i + 1) * P) for i in kept]
            + [self.num_fingers * P + np.arange(i * V, (i + 1) * V) for i in kept]
        )
        self.num_rows = np.full(num_knots, self._kept.size)
        f = body.hand.fingers
        self._p_W_base, self._psi, self._l1 = f.p_W_base, f.psi, f.l1  # (4, 2), (4,), (4,)
        # per face (n_x, n_y, offset) as floats: the sums over faces run elementwise, left to right
        self._faces = [(float(n[0]), float(n[1]), float(h)) for n, h in zip(body.normals, body.offsets)]
        pts = self.points
        self._scalars = tuple(  # values_one's constants as Python floats
            (
                float(f.psi[i]),
                float(f.l1[i]),
                float(f.p_W_base[i, 0]),
                float(f.p_W_base[i, 1]),
                tuple(
                    (bool(link), float(p[0]), float(p[1]), float(w))
                    for link, p, w in zip(pts.link, pts.p_JL[i], pts.half_width[i])
                ),
                (
                    *map(float, self._box2.p_JG[i]),
                    float(self._box2.angle_JG[i]),
                    float(self._box2.half_length[i]),
                    float(self._box2.half_width[i]),
                ),
            )
            for i in range(self.num_fingers)
        )

    def knot(self, k: int) -> LinkRows:
        """Knot k's rows alone: these, as no row depends on the knot (evaluate takes any batch size)."""
        return self

    @staticmethod
    def block(x, q) -> np.ndarray:
        """A knot's (x, q) block (link size,) from its pose and joint angles."""
        return np.concatenate([np.asarray(x, dtype=float), np.asarray(q, dtype=float)])

    def bounds(self, clearance: float, fixed_states=()):
        """(lower, upper) of one knot's rows: each row >= clearance (m), but no more than it has
        at any of `fixed_states` ((x, q) pairs: the program's fixed end knots, the search's
        nodes). The search clears the link boxes by its exact test, which may leave a row within
        the clearance, or (where a smooth distance is conservative, beyond a corner) below 0:
        the knots next to the node could not get out in time."""
        lower = np.full(int(self.num_rows[0]), float(clearance))
        for x, q in fixed_states:
            lower = np.minimum(lower, self.values_one(self.block(x, q)))
        return lower, np.full(lower.size, np.inf)

    def sparsity(self) -> list[tuple[int, int]]:
        """(row, col) entries of one knot's Jacobian that can be nonzero: the object's pose,
        the finger's joint 1, and its joint 2 for points on link 2."""
        out, P, V = [], self.points.per_finger, len(self._vertices)
        for i in range(self.num_fingers):
            for j, link in enumerate(self.points.link):
                cols = [*COL_P, COL_TH, int(self.col_q[i, 0])] + ([int(self.col_q[i, 1])] if link else [])
                out += [(i * P + j, c) for c in cols]
        for i in range(self.num_fingers):
            out += [
                (self.num_fingers * P + i * V + j, c)
                for j in range(V)
                for c in (*COL_P, COL_TH, *map(int, self.col_q[i]))
            ]
        position = {int(row): n for n, row in enumerate(self._kept)}
        return [(position[row], col) for row, col in out if row in position]

    def _lse(self, d: list):
        """(phi, weights) of the log-sum-exp of the face distances d (arrays), elementwise and
        left to right: contact.smooth_distance's phi; its gradient is sum_j weights_j n_j."""
        k = self.body.sharpness
        dmax = d[0]
        for dj in d[1:]:
            dmax = np.maximum(dmax, dj)
        e = [np.exp(k * (dj - dmax)) for dj in d]
        total = 0.0
        for ej in e:
            total = total + ej
        return dmax + np.log(total) / k, [ej / total for ej in e]

    def evaluate(self, Z: np.ndarray, with_jacobian: bool):
        """(values (K, R), Jacobians (K, R, link size) or None) at the (x, q) blocks Z (K, link size):
        the point rows (finger-major), then the vertex rows (finger-major)."""
        q = Z[:, self.col_q]  # (K, F, 2)
        a1 = self._psi + q[..., 0]  # (K, 4)
        a12 = a1 + q[..., 1]
        th = Z[:, COL_TH, None, None]
        c1, s1 = np.cos(a1), np.sin(a1)
        kin = _Kinematics(
            c1=c1,
            s1=s1,
            c12=np.cos(a12),
            s12=np.sin(a12),
            ct=np.cos(th),
            st=np.sin(th),
            elbow_x=self._p_W_base[:, 0] + self._l1 * c1,
            elbow_y=self._p_W_base[:, 1] + self._l1 * s1,
        )
        parts = [self._point_rows(Z, kin, with_jacobian), self._vertex_rows(Z, kin, a12, with_jacobian)]
        val = np.concatenate([v for v, _ in parts], axis=1)[:, self._kept]
        return val, (np.concatenate([j for _, j in parts], axis=1)[:, self._kept] if with_jacobian else None)

    def _joint_columns(self, jac, d_q1, d_q2) -> None:
        """jac (K, F, n, link size)[..., col_q[i]] = d_q1, d_q2 (K, F, n) of each finger i."""
        fingers = np.arange(self.num_fingers)
        jac[:, fingers, :, self.col_q[:, 0]] = d_q1.transpose(1, 0, 2)
        jac[:, fingers, :, self.col_q[:, 1]] = d_q2.transpose(1, 0, 2)

    def _point_rows(self, Z, kin, with_jacobian: bool):
        pts, nK = self.points, Z.shape[0]
        on2 = pts.link.astype(bool)  # (P,)
        # the frame J of each point's link: origin and angle (K, 4, P)
        ox = np.where(on2, kin.elbow_x[..., None], self._p_W_base[:, 0, None])
        oy = np.where(on2, kin.elbow_y[..., None], self._p_W_base[:, 1, None])
        c = np.where(on2, kin.c12[..., None], kin.c1[..., None])
        s = np.where(on2, kin.s12[..., None], kin.s1[..., None])
        lx, ly = pts.p_JL[..., 0], pts.p_JL[..., 1]  # (4, P)
        wx, wy = ox + (c * lx - s * ly), oy + (s * lx + c * ly)  # p_WL
        rx, ry = wx - Z[:, 0, None, None], wy - Z[:, 1, None, None]
        ct, st = kin.ct, kin.st
        bx, by = ct * rx + st * ry, -st * rx + ct * ry  # p_BL = R^T (p_WL - p)
        phi, w = self._lse([nx * bx + ny * by - h for nx, ny, h in self._faces])
        val = (phi - pts.half_width).reshape(nK, -1)
        if not with_jacobian:
            return val, None
        gx, gy = _weighted(w, [(nx, ny) for nx, ny, _ in self._faces])
        gwx, gwy = ct * gx - st * gy, st * gx + ct * gy  # R g = d phi / d p_WL
        jac = np.zeros((nK, self.num_fingers, pts.per_finger, self.link_size))
        jac[..., COL_P[0]], jac[..., COL_P[1]] = -gwx, -gwy
        jac[..., COL_TH] = gwx * ry - gwy * rx  # d p_BL / d theta = -R^T K (p_WL - p)
        # joint 1 turns every point about the base, joint 2 the link-2 points about the elbow
        d_q1 = gwy * (wx - self._p_W_base[:, 0, None]) - gwx * (wy - self._p_W_base[:, 1, None])
        d_q2 = np.where(on2, gwy * (wx - kin.elbow_x[..., None]) - gwx * (wy - kin.elbow_y[..., None]), 0.0)
        self._joint_columns(jac, d_q1, d_q2)
        return val, jac.reshape(nK, -1, self.link_size)

    def _vertex_rows(self, Z, kin, a12, with_jacobian: bool):
        """Each object vertex's smooth distance to each finger's link-2 box, in the box's frame G."""
        box, nK = self._box2, Z.shape[0]
        vx, vy = self._vertices[:, 0], self._vertices[:, 1]  # (V,)
        ct, st = kin.ct, kin.st  # (K, 1, 1)
        wx = Z[:, 0, None, None] + (ct * vx - st * vy)  # p_WV (K, 1, V)
        wy = Z[:, 1, None, None] + (st * vx + ct * vy)
        ox = kin.elbow_x + (kin.c12 * box.p_JG[:, 0] - kin.s12 * box.p_JG[:, 1])  # G's origin (K, 4)
        oy = kin.elbow_y + (kin.s12 * box.p_JG[:, 0] + kin.c12 * box.p_JG[:, 1])
        A = a12 + box.angle_JG
        cA, sA = np.cos(A)[..., None], np.sin(A)[..., None]  # (K, 4, 1)
        rx, ry = wx - ox[..., None], wy - oy[..., None]  # (K, 4, V)
        gx_, gy_ = cA * rx + sA * ry, -sA * rx + cA * ry  # p_GV
        hl, hw = box.half_length[:, None], box.half_width[:, None]
        phi, w = self._lse([gx_ - hl, -gx_ - hl, gy_ - hw, -gy_ - hw])
        val = phi.reshape(nK, -1)
        if not with_jacobian:
            return val, None
        gx, gy = w[0] - w[1], w[2] - w[3]  # gradient in G
        gwx, gwy = cA * gx - sA * gy, sA * gx + cA * gy  # in W
        jac = np.zeros((nK, self.num_fingers, len(vx), self.link_size))
        jac[..., COL_P[0]], jac[..., COL_P[1]] = gwx, gwy
        jac[..., COL_TH] = gwy * (wx - Z[:, 0, None, None]) - gwx * (wy - Z[:, 1, None, None])
        # the box turns about the base (joint 1) and the elbow (joint 2): p_GV moves the other way
        d_q1 = gwx * (wy - self._p_W_base[:, 1, None]) - gwy * (wx - self._p_W_base[:, 0, None])
        d_q2 = gwx * (wy - kin.elbow_y[..., None]) - gwy * (wx - kin.elbow_x[..., None])
        self._joint_columns(jac, d_q1, d_q2)
        return val, jac.reshape(nK, -1, self.link_size)

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows at one block z (link size,): `evaluate`'s arithmetic in Python floats, 2.5x
        faster for one knot (IPOPT asks for values at each trial point knot by knot); math's
        exp and log may differ from numpy's in the last bit (tests compare them to 1e-15)."""
        px, py, th, *q = z.tolist()
        ct, st = math.cos(th), math.sin(th)
        k, faces = self.body.sharpness, self._faces
        vertices = [(px + (ct * vx - st * vy), py + (st * vx + ct * vy)) for vx, vy in self._vertices.tolist()]
        point_rows, vertex_rows = [], []
        for i in self.fingers:
            psi, l1, base_x, base_y, points, box = self._scalars[i]
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
                point_rows.append(_lse_one([nx * bx + ny * by - h for nx, ny, h in faces], k) - w)
            gjx, gjy, angle, hl, hw = box
            ox, oy = elbow_x + (c12 * gjx - s12 * gjy), elbow_y + (s12 * gjx + c12 * gjy)
            cA, sA = math.cos(a12 + angle), math.sin(a12 + angle)
            for wx, wy in vertices:
                rx, ry = wx - ox, wy - oy
                gx, gy = cA * rx + sA * ry, -sA * rx + cA * ry
                vertex_rows.append(_lse_one([gx - hl, -gx - hl, gy - hw, -gy - hw], k))
        return np.array(point_rows + vertex_rows)


def _lse_one(d: list, k: float) -> float:
    """LinkRows._lse's phi for one point, in Python floats."""
    dmax = max(d)
    total = 0.0
    for dj in d:
        total += math.exp(k * (dj - dmax))
    return dmax + math.log(total) / k
