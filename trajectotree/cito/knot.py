"""The nonlinear rows of every knot: object and hand dynamics plus each finger's
contact rows, with an analytic Jacobian, vectorized over knots and fingers.

Each finger at each knot is either *pinned* (TrajectoTree's fixed fingers, and a
switching finger at its segment's ends: the fingertip centre must be at a planned
point c_B = p*_BC + r n*_B of the object, relaxed by the finger's slack, and the
contact frame is the planned one), or *free* (general CITO: the contact frame comes
from the smooth distance to the object (any convex polygon) at the fingertip, with non-penetration and the
relaxed complementarity rows of eqs. 5-6).

Rows of knot k (on its variables, see variables.knot_block; named in layout.py):
  object (3):  m p_dd - sum f_W - m g = 0;  I theta_dd - sum (p_WC - p_WB) x f_W = 0
  hand (2F):    M(q) q_dd - tau - tau_g(q) + J_C^T f_W = 0, J_C the Jacobian of the
               contact point p_WC = p_WF - r n_W on link 2 (J_C^T f = J_F^T f - r lambda_t [1, 1])
  pinned (4):  gamma -/+ (p_WF - p_WB - R c_B) >= 0
  free (6):    phi(p_BF) - r >= 0;  gamma - (phi - r) lambda_n >= 0;
               gamma -/+ v_rel,a lambda_n >= 0 for a in {x, y} (eq. 6, W components),
               v_rel = J_F q_d - (p_d + theta_d z x (p_WF - p_WB))
with f_W = R (-lambda_n n_B + lambda_t t_B), t_B = z x n_B: the force of the finger
on the box. Hand gravity is included (a deviation from the paper's eq. 3, so that
tau is the physical torque); Coriolis terms are omitted as in the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trajectotree.cito.contact import smooth_distance, smooth_normal
from trajectotree.cito.knot_jacobian import knot_jacobian
from trajectotree.cito.layout import (
    COL_P,
    COL_PD,
    COL_PDD,
    COL_TH,
    COL_THD,
    COL_THDD,
    FREE_COMP,
    FREE_PHI,
    FREE_ROWS,
    FREE_SLIP,
    PIN_MINUS,
    PIN_PLUS,
    PINNED_ROWS,
    ROW_FORCE,
    ROW_MOMENT,
    TWO,
    knot_layout,
)
from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.kinematics import K90, jacobian_from_links


class BodyParams:
    """The constants the rows need, read once from the scene. `mu` is the friction
    coefficient the plan may use (mu_plan = search.friction_safety * scene.mu, see
    config.mu_plan), not necessarily the scene's."""

    def __init__(self, scene, sharpness: float, *, mu: float):
        c = scene.config
        self.hand = HandModel.from_scene(scene)
        self.fingers = scene.fingers  # the same fingers one by one, for scalar code
        self.mass = c.box_mass
        self.mu = float(mu)
        self.shape = c.shape  # the object's outline (geometry.ConvexPolygon)
        self.inertia = c.inertia_zz()  # for the box bit for bit m (w^2 + h^2) / 12, unless scene.object_inertia
        self.gravity = np.array([0.0, -c.gravity])
        self.radius = scene.tip_radius
        self.normals = self.shape.normals  # (V, 2) outward face normals in B
        self.offsets = self.shape.offsets  # (V,) m, face j: normals[j] . p_B = offsets[j]
        self.sharpness = sharpness
        self.link_boxes = tuple(f.link_boxes for f in self.fingers)  # per finger, its links' collision boxes (links.py)
        self.layout = knot_layout(len(self.fingers))  # the knot block's columns and rows for this hand


def _rot(th):
    c, s = np.cos(th), np.sin(th)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (K, 2, 2)


@dataclass(frozen=True)
class KnotKinematics:
    """Per-finger quantities of a batch of K knots (shapes (K, 4, ...) unless noted)."""

    R: np.ndarray  # (K, 2, 2) R_WB, the box's rotation
    RT: np.ndarray  # (K, 2, 2) R_WB^T
    r1: np.ndarray  # (K, 4, 2) m, link-1 vectors
    r2: np.ndarray  # (K, 4, 2) m, link-2 vectors
    J: np.ndarray  # (K, 4, 2, 2) m/rad, fingertip Jacobians J_WF
    p_WF: np.ndarray  # (K, 4, 2) m, fingertip centres in W
    rel: np.ndarray  # (K, 4, 2) m, p_WF - p_WB
    p_BF: np.ndarray  # (K, 4, 2) m, fingertip centres in B
    grad: np.ndarray  # (K, 4, 2) gradient of the smooth object distance at p_BF
    dn_s: np.ndarray  # (K, 4, 2, 2) 1/m, d n_B / d p_BF of the smooth normal
    n_W: np.ndarray  # (K, 4, 2) contact normal in W (the planned one for pinned fingers)
    t_W: np.ndarray  # (K, 4, 2) contact tangent z x n_W
    f_W: np.ndarray  # (K, 4, 2) N, force of the finger on the box in W
    arm: np.ndarray  # (K, 4, 2) m, p_WC - p_WB
    p_WC: np.ndarray  # (K, 4, 2) m, contact points p_WF - r n_W
    phi_tip: np.ndarray  # (K, 4) m, smooth distance of the tip sphere from the object (phi - r)
    e: np.ndarray  # (K, 4, 2) m, pinned-point error p_WF - p_WB - R c_B
    v: np.ndarray  # (K, 4, 2) m/s, fingertip velocity relative to the box point under it


def _smooth_contact(bx: float, by: float, k: float, faces: tuple, radius: float):
    """(phi - r, n_B) of contact.smooth_distance at the tip centre (bx, by) in B, in math;
    faces: per face (n_x, n_y, offset). Sums run left to right (no sum(): Python 3.12's is
    compensated): for the box, 1.0 bx + 0.0 by - w/2 is bx - w/2 and e_0 1.0 + e_1 0.0 +
    e_2 (-1.0) + e_3 0.0 is e_0 - e_2 exactly, the numbers the box's plans were made with."""
    d = [nx * bx + ny * by - h for nx, ny, h in faces]
    dmax = max(d)
    total = gx = gy = 0.0
    for dj, (nx, ny, _) in zip(d, faces):
        e = math.exp(k * (dj - dmax))
        total += e
        gx += e * nx
        gy += e * ny
    gx, gy = gx / total, gy / total
    norm = math.hypot(gx, gy)
    return dmax + math.log(total) / k - radius, gx / norm, gy / norm


def _scalar_constants(rows: KnotRows):
    """values_one's constants of a one-knot batch as Python floats: the body's
    (m, g_x, g_y, I, r, sharpness, faces: per face (n_x, n_y, offset)) and per finger
    (psi, l1, l2, p_W_base, mass_a, mass_b, mass_c, grav_1, grav_2, pinned, n_B, c_B)."""
    b, hand = rows.body, rows.body.hand
    faces = tuple((float(n[0]), float(n[1]), float(h)) for n, h in zip(b.normals, b.offsets))
    body = tuple(float(v) for v in (b.mass, *b.gravity, b.inertia, b.radius, b.sharpness)) + (faces,)
    fingers = tuple(
        (
            float(f.psi),
            float(f.l1),
            float(f.l2),
            *map(float, f.p_W_base),
            float(hand.mass_a[i]),
            float(hand.mass_b[i]),
            float(hand.mass_c[i]),
            float(hand.grav_1[i]),
            float(hand.grav_2[i]),
            bool(rows.pinned[0, i]),
            *map(float, rows.n_B[0, i]),
            *map(float, rows.c_B[0, i]),
        )
        for i, f in enumerate(b.fingers)
    )
    return body, fingers


class KnotRows:
    """The rows of a batch of knots. pinned (K, F) selects each finger's mode;
    c_B, n_B (K, F, 2) are the pinned fingertip-centre targets and normals in B."""

    def __init__(self, body: BodyParams, pinned, c_B, n_B):
        self.body = body
        L = self.layout = body.layout
        self.pinned = np.asarray(pinned, dtype=bool).reshape(-1, L.num_fingers)
        self.c_B = np.asarray(c_B, dtype=float).reshape(-1, L.num_fingers, 2)
        self.n_B = np.asarray(n_B, dtype=float).reshape(-1, L.num_fingers, 2)
        sizes = np.where(self.pinned, PINNED_ROWS, FREE_ROWS)
        self.row_start = L.num_body_rows + np.cumsum(sizes, axis=1) - sizes
        self.num_rows = L.num_body_rows + sizes.sum(axis=1)  # (K,)
        self.kP, self.iP = np.nonzero(self.pinned)
        self.kF, self.iF = np.nonzero(~self.pinned)
        self._scalars = None  # values_one's constants, made on its first call
        self.index_cache = {}  # knot_jacobian's flat scatter positions, made on first use

    def knot(self, k: int) -> KnotRows:
        return KnotRows(self.body, self.pinned[k : k + 1], self.c_B[k : k + 1], self.n_B[k : k + 1])

    def bounds(self, k: int, clearance):
        """(lower, upper) of knot k's rows; `clearance` (4,) m is the lower bound of each
        free finger's non-penetration row phi - r >= clearance."""
        n, L = self.num_rows[k], self.layout
        lower = np.zeros(n)
        free = ~self.pinned[k]
        lower[self.row_start[k, free] + FREE_PHI] = np.asarray(clearance, dtype=float)[free]
        return lower, np.concatenate([np.zeros(L.num_body_rows), np.full(n - L.num_body_rows, np.inf)])

    def kinematics(self, Z: np.ndarray) -> KnotKinematics:
        """The per-finger quantities of knots Z (K, knot size)."""
        b, hand, r, L = self.body, self.body.hand, self.body.radius, self.layout
        nK = Z.shape[0]
        p, th, pd, thd = Z[:, COL_P], Z[:, COL_TH], Z[:, COL_PD], Z[:, COL_THD]
        q, qd = Z[:, L.block.slices["q"]], Z[:, L.block.slices["qd"]].reshape(nK, L.num_fingers, 2)
        ln, lt = Z[:, L.block.slices["lambda_n"]], Z[:, L.block.slices["lambda_t"]]
        R = _rot(th)
        RT = R.transpose(0, 2, 1)
        r1, r2 = hand.links(q)  # (K, 4, 2)
        J = jacobian_from_links(r1, r2)  # (K, 4, 2, 2)
        p_WF = hand.fingers.tip_from_links(r1, r2)
        rel = p_WF - p[:, None]  # p_WF - p_WB
        p_BF = rel @ R  # R^T rel
        phi, grad, hess = smooth_distance(p_BF.reshape(-1, 2), b.normals, b.offsets, b.sharpness)
        n_s, dn_s = smooth_normal(grad, hess)
        n_B = np.where(self.pinned[..., None], self.n_B, n_s.reshape(nK, L.num_fingers, 2))
        n_W = n_B @ RT
        t_W = n_W @ K90.T
        f_W = -ln[..., None] * n_W + lt[..., None] * t_W
        return KnotKinematics(
            R=R,
            RT=RT,
            r1=r1,
            r2=r2,
            J=J,
            p_WF=p_WF,
            rel=rel,
            p_BF=p_BF,
            grad=grad.reshape(nK, L.num_fingers, 2),
            dn_s=dn_s.reshape(nK, L.num_fingers, 2, 2),
            n_W=n_W,
            t_W=t_W,
            f_W=f_W,
            arm=rel - r * n_W,
            p_WC=p_WF - r * n_W,
            phi_tip=phi.reshape(nK, L.num_fingers) - r,
            e=rel - self.c_B @ RT,
            v=np.einsum("kiab,kib->kia", J, qd) - pd[:, None] - thd[:, None, None] * (rel @ K90.T),
        )

    def evaluate(self, Z: np.ndarray, with_jacobian: bool):
        """(values (K, R), Jacobians (K, R, knot size) or None), R = max rows; knot k
        uses its first num_rows[k] rows. The Jacobian is analytic (knot_jacobian.py)."""
        kin = self.kinematics(Z)
        val = self._values(Z, kin)
        return val, (knot_jacobian(self, Z, kin) if with_jacobian else None)

    def _values(self, Z: np.ndarray, kin: KnotKinematics) -> np.ndarray:
        b, hand, r, L = self.body, self.body.hand, self.body.radius, self.layout
        nK = Z.shape[0]
        q = Z[:, L.block.slices["q"]]
        qdd, tau = (Z[:, L.block.slices[n]].reshape(nK, L.num_fingers, 2) for n in ("qdd", "tau"))
        ln, lt, gam = Z[:, L.block.slices["lambda_n"]], Z[:, L.block.slices["lambda_t"]], Z[:, L.block.slices["slack"]]
        f_W, arm, e, v, phi_tip = kin.f_W, kin.arm, kin.e, kin.v, kin.phi_tip
        val = np.zeros((nK, int(self.num_rows.max())))
        val[:, ROW_FORCE] = b.mass * Z[:, COL_PDD] - f_W.sum(1) - b.mass * b.gravity
        val[:, ROW_MOMENT] = b.inertia * Z[:, COL_THDD] - np.sum(
            arm[..., 0] * f_W[..., 1] - arm[..., 1] * f_W[..., 0], axis=1
        )
        val[:, L.row_hand] = (
            np.einsum("kiab,kib->kia", hand.mass_matrices(q), qdd)
            - tau
            - hand.gravity_forces(q)
            + np.einsum("kiab,kia->kib", kin.J, f_W)
            - r * lt[..., None]
        ).reshape(nK, -1)
        kP, iP, kF, iF = self.kP, self.iP, self.kF, self.iF
        rp, rf = self.row_start[kP, iP], self.row_start[kF, iF]
        val[kP[:, None], rp[:, None] + PIN_MINUS + TWO] = gam[kP, iP, None] - e[kP, iP]
        val[kP[:, None], rp[:, None] + PIN_PLUS + TWO] = gam[kP, iP, None] + e[kP, iP]
        lnF = ln[kF, iF]
        val[kF, rf + FREE_PHI] = phi_tip[kF, iF]
        val[kF, rf + FREE_COMP] = gam[kF, iF] - phi_tip[kF, iF] * lnF
        vl = v[kF, iF] * lnF[:, None]
        val[kF[:, None], rf[:, None] + FREE_SLIP + 2 * TWO] = gam[kF, iF, None] - vl
        val[kF[:, None], rf[:, None] + FREE_SLIP + 1 + 2 * TWO] = gam[kF, iF, None] + vl
        return val

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows of a one-knot batch at z (knot size,), several times faster than
        `evaluate` for one knot (IPOPT asks for the values at each trial point knot by
        knot). Scalar on purpose, the same rows as `_values` in the same order: numpy's
        exp, log, norm and matmul round differently from math's in the last bit, and IPOPT
        has always seen these exact numbers (values from `evaluate` instead change the
        s2cito plan: 118 IPOPT iterations, not 130; the shared vectorized kinematics here
        cost 2.5x the time of this function). The constants are Python floats
        (`_scalar_constants`): the same doubles, without numpy's per-scalar overhead; the
        finger's FK is TwoLinkFinger.links_one's arithmetic, inlined."""
        if self._scalars is None:
            self._scalars = _scalar_constants(self)
        (m, gx, gy, inertia, r, k, faces), fingers = self._scalars
        L = self.layout
        z = z.tolist()
        (px, py), th, (pdx, pdy), thd = z[COL_P], z[COL_TH], z[COL_PD], z[COL_THD]
        q, qd, qdd, tau = (z[L.block.slices[n]] for n in ("q", "qd", "qdd", "tau"))
        lns, lts, gams = (z[L.block.slices[n]] for n in ("lambda_n", "lambda_t", "slack"))
        c, s = math.cos(th), math.sin(th)
        fx_sum = fy_sum = torque = 0.0
        hand_rows, contact_rows = [], []
        for i, (psi, l1, l2, basex, basey, ma, mb, mc, g1, g2, pinned, nbx, nby, cbx, cby) in enumerate(fingers):
            a1 = psi + q[2 * i]
            a12 = a1 + q[2 * i + 1]
            r1x, r1y, r2x, r2y = l1 * math.cos(a1), l1 * math.sin(a1), l2 * math.cos(a12), l2 * math.sin(a12)
            relx, rely = basex + r1x + r2x - px, basey + r1y + r2y - py
            ln, lt, gam = lns[i], lts[i], gams[i]
            if not pinned:
                phi_tip, nbx, nby = _smooth_contact(c * relx + s * rely, -s * relx + c * rely, k, faces, r)
            nwx, nwy = c * nbx - s * nby, s * nbx + c * nby
            fx, fy = -ln * nwx - lt * nwy, -ln * nwy + lt * nwx
            fx_sum += fx
            fy_sum += fy
            torque += (relx - r * nwx) * fy - (rely - r * nwy) * fx
            u1 = -(r1y + r2y) * fx + (r1x + r2x) * fy
            u2 = -r2y * fx + r2x * fy
            # HandModel.mass_matrices and gravity_forces, in scalars
            cq2 = math.cos(q[2 * i + 1])
            m11, m12, m22 = ma + 2 * mb * cq2, mc + mb * cq2, mc
            t2 = -g2 * math.cos(a12)
            t1 = -g1 * math.cos(a1) + t2
            qdd1, qdd2 = qdd[2 * i : 2 * i + 2]
            hand_rows += [
                m11 * qdd1 + m12 * qdd2 - tau[2 * i] - t1 + u1 - r * lt,
                m12 * qdd1 + m22 * qdd2 - tau[2 * i + 1] - t2 + u2 - r * lt,
            ]
            if pinned:
                ex, ey = relx - (c * cbx - s * cby), rely - (s * cbx + c * cby)
                contact_rows += [gam - ex, gam - ey, gam + ex, gam + ey]
            else:
                qd1, qd2 = qd[2 * i : 2 * i + 2]
                vx = -(r1y + r2y) * qd1 - r2y * qd2 - pdx + thd * rely
                vy = (r1x + r2x) * qd1 + r2x * qd2 - pdy - thd * relx
                contact_rows += [
                    phi_tip,
                    gam - phi_tip * ln,
                    gam - vx * ln,
                    gam + vx * ln,
                    gam - vy * ln,
                    gam + vy * ln,
                ]
        return np.array(
            [m * z[COL_PDD][0] - fx_sum - m * gx, m * z[COL_PDD][1] - fy_sum - m * gy, inertia * z[COL_THDD] - torque]
            + hand_rows
            + contact_rows
        )

    def sparsity(self, k: int) -> list[tuple[int, int]]:
        """(row, col) entries of knot k's Jacobian that can be nonzero (see `sparsities`)."""
        return self.knot(k).sparsities()[0]

    def sparsities(self) -> list[list[tuple[int, int]]]:
        """Per knot, the (row, col) entries of its Jacobian that can be nonzero, from the
        Jacobian at three random points (structural zeros stay exactly zero), every knot
        at the same points, in one batch per point (one evaluation per knot and point cost
        ~35 ms per 13-knot program) of the distinct knots only: a knot's rows depend on
        nothing but its pinned, c_B and n_B (a segment's inner knots share theirs)."""
        keys = [
            self.pinned[k].tobytes() + self.c_B[k].tobytes() + self.n_B[k].tobytes() for k in range(len(self.num_rows))
        ]
        first = {}  # each distinct key's first knot, in order
        for k, key in enumerate(keys):
            first.setdefault(key, k)
        distinct, L = np.array(list(first.values())), self.layout
        rows = KnotRows(self.body, self.pinned[distinct], self.c_B[distinct], self.n_B[distinct])
        rng = np.random.default_rng(0)
        mask = np.zeros((len(distinct), int(rows.num_rows.max()), L.block.size), dtype=bool)
        for _ in range(3):
            z = rng.uniform(-1, 1, (1, L.block.size))
            mask |= rows.evaluate(np.repeat(z, len(distinct), axis=0), True)[1] != 0.0
        patterns = [
            [(int(i), int(j)) for i, j in zip(*np.nonzero(mask[u, : rows.num_rows[u]]))] for u in range(len(distinct))
        ]
        slot = {key: u for u, key in enumerate(first)}
        return [patterns[slot[key]] for key in keys]
