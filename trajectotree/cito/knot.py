"""The nonlinear rows of every knot: object and hand dynamics plus each finger's
contact rows, with an analytic Jacobian, vectorized over knots and fingers.

Each finger at each knot is either *pinned* (TrajectoTree's fixed fingers, and a
switching finger at its segment's ends: the fingertip centre must be at a planned
point c_B = p*_BC + r n*_B of the box, relaxed by the finger's slack, and the
contact frame is the planned one), or *free* (general CITO: the contact frame comes
from the smooth box distance at the fingertip, with non-penetration and the
relaxed complementarity rows of eqs. 5-6).

Rows of knot k (on its KNOT_SIZE variables, see variables.GROUPS):
  object (3):  m p_dd - sum f_W - m g = 0;  I theta_dd - sum (p_WC - p_WB) x f_W = 0
  hand (8):    M(q) q_dd - tau - tau_g(q) + J_C^T f_W = 0, J_C the Jacobian of the
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
from types import SimpleNamespace

import numpy as np

from trajectotree.cito.contact import face_offsets, smooth_distance, smooth_normal
from trajectotree.cito.hand import K90, HandModel
from trajectotree.cito.variables import KNOT_SIZE, SLICES
from trajectotree.scene import NUM_FINGERS

_I2 = np.eye(2)
_F = np.arange(NUM_FINGERS)
_COL_Q, _COL_QD, _COL_QDD, _COL_TAU = (SLICES[n].start + 2 * _F[:, None] + np.arange(2) for n in ("q", "qd", "qdd", "tau"))
_COL_LN, _COL_LT, _COL_G = (SLICES[n].start + _F for n in ("lambda_n", "lambda_t", "slack"))
_ROW_HAND = 3 + 2 * _F[:, None] + np.arange(2)                        # (4, 2)
NUM_BODY_ROWS, PINNED_ROWS, FREE_ROWS = 11, 4, 6


class BodyParams:
    """The constants the rows need, read once from the scene. `mu` is the friction
    coefficient the plan may use (mu_plan = search.friction_safety * scene.mu, see
    planners.planning_mu), not necessarily the scene's."""

    def __init__(self, scene, sharpness: float, *, mu: float):
        c = scene.config
        self.hand = HandModel.from_scene(scene)
        self.mass = c.box_mass
        self.mu = float(mu)
        self.inertia = c.box_mass * (c.box_width ** 2 + c.box_height ** 2) / 12.0
        self.gravity = np.array([0.0, -c.gravity])
        self.radius = scene.tip_radius
        self.offsets = face_offsets(c.box_width, c.box_height)
        self.sharpness = sharpness


def _rot(th):
    c, s = np.cos(th), np.sin(th)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)   # (K, 2, 2)


class KnotRows:
    """The rows of a batch of knots. pinned (K, 4) selects each finger's mode;
    c_B, n_B (K, 4, 2) are the pinned fingertip-centre targets and normals in B."""

    def __init__(self, body: BodyParams, pinned, c_B, n_B):
        self.body = body
        self.pinned = np.asarray(pinned, dtype=bool).reshape(-1, NUM_FINGERS)
        self.c_B = np.asarray(c_B, dtype=float).reshape(-1, NUM_FINGERS, 2)
        self.n_B = np.asarray(n_B, dtype=float).reshape(-1, NUM_FINGERS, 2)
        sizes = np.where(self.pinned, PINNED_ROWS, FREE_ROWS)
        self.row_start = NUM_BODY_ROWS + np.cumsum(sizes, axis=1) - sizes
        self.num_rows = NUM_BODY_ROWS + sizes.sum(axis=1)               # (K,)
        self.kP, self.iP = np.nonzero(self.pinned)
        self.kF, self.iF = np.nonzero(~self.pinned)

    def knot(self, k: int) -> "KnotRows":
        return KnotRows(self.body, self.pinned[k:k + 1], self.c_B[k:k + 1], self.n_B[k:k + 1])

    def bounds(self, k: int, clearance):
        """(lower, upper) of knot k's rows; `clearance` (4,) m is the lower bound of each
        free finger's non-penetration row phi - r >= clearance."""
        n = self.num_rows[k]
        lower = np.zeros(n)
        free = ~self.pinned[k]
        lower[self.row_start[k, free]] = np.asarray(clearance, dtype=float)[free]
        return lower, np.concatenate([np.zeros(NUM_BODY_ROWS), np.full(n - NUM_BODY_ROWS, np.inf)])

    def kinematics(self, Z: np.ndarray) -> SimpleNamespace:
        """The per-finger quantities of knots Z (K, KNOT_SIZE), each (K, 4, ...): fingertip
        p_WF, contact point p_WC, normal/tangent/force in W, smooth distance of the tip
        phi_tip, relative velocity v, pinned-point error e, and the internals evaluate needs."""
        b, hand, r = self.body, self.body.hand, self.body.radius
        nK = Z.shape[0]
        p, th, pd, thd = Z[:, 0:2], Z[:, 2], Z[:, 3:5], Z[:, 5]
        q, qd = Z[:, SLICES["q"]], Z[:, SLICES["qd"]].reshape(nK, NUM_FINGERS, 2)
        ln, lt = Z[:, SLICES["lambda_n"]], Z[:, SLICES["lambda_t"]]
        R = _rot(th)
        RT = R.transpose(0, 2, 1)
        r1, r2 = hand.links(q)                                           # (K, 4, 2)
        J = hand.jacobians_from_links(r1, r2)                            # (K, 4, 2, 2)
        p_WF = hand.base + r1 + r2
        rel = p_WF - p[:, None]                                          # p_WF - p_WB
        p_BF = rel @ R                                                   # R^T rel
        phi, grad, hess = smooth_distance(p_BF.reshape(-1, 2), b.offsets, b.sharpness)
        n_s, dn_s = smooth_normal(grad, hess)
        n_B = np.where(self.pinned[..., None], self.n_B, n_s.reshape(nK, NUM_FINGERS, 2))
        n_W = n_B @ RT
        t_W = n_W @ K90.T
        f_W = -ln[..., None] * n_W + lt[..., None] * t_W
        return SimpleNamespace(
            R=R, RT=RT, r1=r1, r2=r2, J=J, p_WF=p_WF, rel=rel, p_BF=p_BF, grad=grad.reshape(nK, NUM_FINGERS, 2),
            dn_s=dn_s.reshape(nK, NUM_FINGERS, 2, 2), n_W=n_W, t_W=t_W, f_W=f_W, arm=rel - r * n_W,
            p_WC=p_WF - r * n_W, phi_tip=phi.reshape(nK, NUM_FINGERS) - r, e=rel - self.c_B @ RT,
            v=np.einsum("kiab,kib->kia", J, qd) - pd[:, None] - thd[:, None, None] * (rel @ K90.T))

    def evaluate(self, Z: np.ndarray, with_jacobian: bool):
        """(values (K, R), Jacobians (K, R, KNOT_SIZE) or None), R = max rows; knot k
        uses its first num_rows[k] rows."""
        b, hand, r = self.body, self.body.hand, self.body.radius
        nK = Z.shape[0]
        p, th, pd, thd = Z[:, 0:2], Z[:, 2], Z[:, 3:5], Z[:, 5]
        xdd, q = Z[:, SLICES["xdd"]], Z[:, SLICES["q"]]
        qdd, tau = (Z[:, SLICES[n]].reshape(nK, NUM_FINGERS, 2) for n in ("qdd", "tau"))
        ln, lt, gam = Z[:, SLICES["lambda_n"]], Z[:, SLICES["lambda_t"]], Z[:, SLICES["slack"]]
        kin = self.kinematics(Z)
        R, RT, J, r1, r2, rel, p_BF = kin.R, kin.RT, kin.J, kin.r1, kin.r2, kin.rel, kin.p_BF
        grad, n_W, t_W, f_W, arm, e, v, phi_tip = (kin.grad, kin.n_W, kin.t_W, kin.f_W, kin.arm, kin.e,
                                                    kin.v, kin.phi_tip)
        pin = self.pinned[..., None]
        qd = Z[:, SLICES["qd"]].reshape(nK, NUM_FINGERS, 2)
        M = hand.mass_matrices(q)

        R_max = int(self.num_rows.max())
        val = np.zeros((nK, R_max))
        val[:, 0:2] = b.mass * xdd[:, :2] - f_W.sum(1) - b.mass * b.gravity
        val[:, 2] = b.inertia * xdd[:, 2] - np.sum(arm[..., 0] * f_W[..., 1] - arm[..., 1] * f_W[..., 0], axis=1)
        val[:, 3:11] = (np.einsum("kiab,kib->kia", M, qdd) - tau - hand.gravity_forces(q)
                        + np.einsum("kiab,kia->kib", J, f_W) - r * lt[..., None]).reshape(nK, -1)
        kP, iP, kF, iF = self.kP, self.iP, self.kF, self.iF
        rp, rf = self.row_start[kP, iP], self.row_start[kF, iF]
        two = np.arange(2)
        val[kP[:, None], rp[:, None] + two] = gam[kP, iP, None] - e[kP, iP]
        val[kP[:, None], rp[:, None] + 2 + two] = gam[kP, iP, None] + e[kP, iP]
        lnF = ln[kF, iF]
        val[kF, rf] = phi_tip[kF, iF]
        val[kF, rf + 1] = gam[kF, iF] - phi_tip[kF, iF] * lnF
        vl = v[kF, iF] * lnF[:, None]
        val[kF[:, None], rf[:, None] + 2 + 2 * two] = gam[kF, iF, None] - vl
        val[kF[:, None], rf[:, None] + 3 + 2 * two] = gam[kF, iF, None] + vl
        if not with_jacobian:
            return val, None

        jac = np.zeros((nK, R_max, KNOT_SIZE))
        kk = np.arange(nK)[:, None, None]
        # Derivatives of p_BF = R^T (p_WF - p): wrt p (-R^T), theta (-K p_BF), q_i (R^T J_i).
        dpB_dth = -(p_BF @ K90.T)
        dpB_dq = RT[:, None] @ J
        dn_s = np.where(pin[..., None], 0.0, kin.dn_s)
        RdnB = R[:, None] @ dn_s                                         # R dn_B/dp_B
        dnW_dp = -(RdnB @ RT[:, None])
        dnW_dth = n_W @ K90.T + np.einsum("kiab,kib->kia", RdnB, dpB_dth)
        dnW_dq = RdnB @ dpB_dq
        A = -ln[..., None, None] * _I2 + lt[..., None, None] * K90       # f_W = A n_W
        df_dp = A @ dnW_dp
        df_dth = np.einsum("kiab,kib->kia", A, dnW_dth)
        df_dq = A @ dnW_dq
        darm_dp = -_I2 - r * dnW_dp
        darm_dth = -r * dnW_dth
        darm_dq = J - r * dnW_dq
        # Object translation rows.
        jac[:, 0:2, 0:2] = -df_dp.sum(1)
        jac[:, 0:2, 2] = -df_dth.sum(1)
        jac[:, 0:2, 6:8] = b.mass * _I2
        jac[:, 0:2, SLICES["q"]] = -df_dq.transpose(0, 2, 1, 3).reshape(nK, 2, -1)
        jac[:, 0:2, _COL_LN] = n_W.transpose(0, 2, 1)
        jac[:, 0:2, _COL_LT] = -t_W.transpose(0, 2, 1)
        # Object rotation row: d cross(arm, f) = -(K f).d arm + (K arm).d f.
        Kf, Ka = f_W @ K90.T, arm @ K90.T
        jac[:, 2, 0:2] = np.einsum("kia,kiab->kb", Kf, darm_dp) - np.einsum("kia,kiab->kb", Ka, df_dp)
        jac[:, 2, 2] = np.sum(Kf * darm_dth, axis=(1, 2)) - np.sum(Ka * df_dth, axis=(1, 2))
        jac[:, 2, 8] = b.inertia
        jac[:, 2, SLICES["q"]] = (np.einsum("kia,kiab->kib", Kf, darm_dq)
                                  - np.einsum("kia,kiab->kib", Ka, df_dq)).reshape(nK, -1)
        jac[:, 2, _COL_LN] = np.sum(Ka * n_W, axis=2)
        jac[:, 2, _COL_LT] = -np.sum(Ka * t_W, axis=2)
        # Hand rows: d(J^T f)/dq = [[-(r1+r2).f, -r2.f], [-r2.f, -r2.f]] + J^T df/dq.
        JT = J.swapaxes(-1, -2)
        a12, a2 = np.sum((r1 + r2) * f_W, -1), np.sum(r2 * f_W, -1)
        H_q = JT @ df_dq - hand.gravity_derivatives(q)
        H_q[..., 0, 0] -= a12
        H_q[..., 0, 1] -= a2
        H_q[..., 1, :] -= a2[..., None]
        H_q[..., :, 1] += np.einsum("kiab,kib->kia", hand.mass_derivatives(q), qdd)
        rows_h, cols_q = _ROW_HAND[None, :, :, None], _COL_Q[None, :, None, :]
        jac[kk[..., None], rows_h, cols_q] = H_q
        jac[kk[..., None], rows_h, _COL_QDD[None, :, None, :]] = M
        jac[kk[..., None], rows_h, _COL_TAU[None, :, None, :]] = -_I2
        jac[:, 3:11, 0:2] = (JT @ df_dp).reshape(nK, 8, 2)
        jac[:, 3:11, 2] = np.einsum("kiab,kib->kia", JT, df_dth).reshape(nK, -1)
        jac[kk, _ROW_HAND[None], _COL_LN[None, :, None]] = -np.einsum("kiab,kib->kia", JT, n_W)
        jac[kk, _ROW_HAND[None], _COL_LT[None, :, None]] = np.einsum("kiab,kib->kia", JT, t_W) - r
        # Pinned rows: gamma -/+ e, e = p_WF - p - R c_B.
        de_dth = -(self.c_B[kP, iP][:, None, :] @ RT[kP])[:, 0] @ K90.T
        kP2, kP3 = kP[:, None], kP[:, None, None]
        for sign, off in ((-1.0, 0), (1.0, 2)):
            rows = rp[:, None] + off + two                                # (nP, 2)
            jac[kP2, rows, _COL_G[iP, None]] = 1.0
            jac[kP3, rows[:, :, None], _COL_Q[iP][:, None, :]] = sign * J[kP, iP]
            jac[kP3, rows[:, :, None], two] = -sign * _I2
            jac[kP2, rows, 2] = sign * de_dth
        # Free rows.
        gF = grad[kF, iF]
        dphi_dp = -(gF[:, None, :] @ RT[kF])[:, 0]
        dphi_dth = np.sum(gF * dpB_dth[kF, iF], 1)
        dphi_dq = np.einsum("na,naj->nj", gF, dpB_dq[kF, iF])
        kF2 = kF[:, None]
        colqF = _COL_Q[iF]
        jac[kF2, rf[:, None], two] = dphi_dp
        jac[kF, rf, 2] = dphi_dth
        jac[kF2, rf[:, None], colqF] = dphi_dq
        r1c = rf + 1
        jac[kF2, r1c[:, None], two] = -lnF[:, None] * dphi_dp
        jac[kF, r1c, 2] = -lnF * dphi_dth
        jac[kF2, r1c[:, None], colqF] = -lnF[:, None] * dphi_dq
        jac[kF, r1c, _COL_LN[iF]] = -phi_tip[kF, iF]
        jac[kF, r1c, _COL_G[iF]] = 1.0
        qdF, r1F, r2F, JF = qd[kF, iF], r1[kF, iF], r2[kF, iF], J[kF, iF]
        dv_dq = -np.stack([(r1F + r2F) * qdF[:, :1] + r2F * qdF[:, 1:], r2F * (qdF[:, :1] + qdF[:, 1:])], axis=2)
        dv_dq -= thd[kF, None, None] * (K90 @ JF)                         # (nF, comp, joint)
        dv_dthd = -(rel[kF, iF] @ K90.T)
        thdK = thd[kF, None, None] * K90                                  # dv/dp
        for a in range(2):
            for sign, off in ((-1.0, 2 + 2 * a), (1.0, 3 + 2 * a)):
                rows = rf + off
                sl = sign * lnF
                jac[kF, rows, _COL_G[iF]] = 1.0
                jac[kF, rows, _COL_LN[iF]] = sign * v[kF, iF, a]
                jac[kF2, rows[:, None], _COL_QD[iF]] = sl[:, None] * JF[:, a, :]
                jac[kF, rows, 3 + a] = -sl
                jac[kF, rows, 5] = sl * dv_dthd[:, a]
                jac[kF2, rows[:, None], colqF] = sl[:, None] * dv_dq[:, a, :]
                jac[kF2, rows[:, None], two] = sl[:, None] * thdK[:, a, :]
        return val, jac

    def values_one(self, z: np.ndarray) -> np.ndarray:
        """The rows of a one-knot batch at z (KNOT_SIZE,), in plain Python scalars: the
        same numbers as `evaluate`, several times faster for one knot (IPOPT asks for
        the values at each trial point knot by knot)."""
        b, hand, r = self.body, self.body.hand, self.body.radius
        z = z.tolist()
        px, py, th, pdx, pdy, thd = z[0:6]
        c, s = math.cos(th), math.sin(th)
        k = b.sharpness
        wa, wb = b.offsets[0], b.offsets[1]
        fx_sum = fy_sum = torque = 0.0
        hand_rows, contact_rows = [], []
        for i in range(NUM_FINGERS):
            q1, q2 = z[9 + 2 * i], z[10 + 2 * i]
            a1 = hand.psi[i] + q1
            a12 = a1 + q2
            c1, s1, c12, s12 = math.cos(a1), math.sin(a1), math.cos(a12), math.sin(a12)
            r1x, r1y, r2x, r2y = hand.l1[i] * c1, hand.l1[i] * s1, hand.l2[i] * c12, hand.l2[i] * s12
            relx, rely = hand.base[i, 0] + r1x + r2x - px, hand.base[i, 1] + r1y + r2y - py
            ln, lt, gam = z[41 + i], z[45 + i], z[49 + i]
            if self.pinned[0, i]:
                nbx, nby = self.n_B[0, i]
            else:
                bx, by = c * relx + s * rely, -s * relx + c * rely
                d = (bx - wa, by - wb, -bx - wa, -by - wb)
                dmax = max(d)
                e = [math.exp(k * (dj - dmax)) for dj in d]
                total = e[0] + e[1] + e[2] + e[3]
                phi_tip = dmax + math.log(total) / k - r
                gx, gy = (e[0] - e[2]) / total, (e[1] - e[3]) / total
                norm = math.hypot(gx, gy)
                nbx, nby = gx / norm, gy / norm
            nwx, nwy = c * nbx - s * nby, s * nbx + c * nby
            fx, fy = -ln * nwx - lt * nwy, -ln * nwy + lt * nwx
            fx_sum += fx
            fy_sum += fy
            torque += (relx - r * nwx) * fy - (rely - r * nwy) * fx
            u1 = -(r1y + r2y) * fx + (r1x + r2x) * fy
            u2 = -r2y * fx + r2x * fy
            cq2 = math.cos(q2)
            m11, m12, m22 = hand.mass_a[i] + 2 * hand.mass_b[i] * cq2, hand.mass_c[i] + hand.mass_b[i] * cq2, hand.mass_c[i]
            t2 = -hand.grav_2[i] * c12
            t1 = -hand.grav_1[i] * c1 + t2
            qdd1, qdd2 = z[25 + 2 * i], z[26 + 2 * i]
            hand_rows += [m11 * qdd1 + m12 * qdd2 - z[33 + 2 * i] - t1 + u1 - r * lt,
                          m12 * qdd1 + m22 * qdd2 - z[34 + 2 * i] - t2 + u2 - r * lt]
            if self.pinned[0, i]:
                cbx, cby = self.c_B[0, i]
                ex, ey = relx - (c * cbx - s * cby), rely - (s * cbx + c * cby)
                contact_rows += [gam - ex, gam - ey, gam + ex, gam + ey]
            else:
                qd1, qd2 = z[17 + 2 * i], z[18 + 2 * i]
                vx = -(r1y + r2y) * qd1 - r2y * qd2 - pdx + thd * rely
                vy = (r1x + r2x) * qd1 + r2x * qd2 - pdy - thd * relx
                contact_rows += [phi_tip, gam - phi_tip * ln, gam - vx * ln, gam + vx * ln, gam - vy * ln, gam + vy * ln]
        m = b.mass
        return np.array([m * z[6] - fx_sum - m * b.gravity[0], m * z[7] - fy_sum - m * b.gravity[1],
                         b.inertia * z[8] - torque] + hand_rows + contact_rows)

    def sparsity(self, k: int) -> list[tuple[int, int]]:
        """(row, col) entries of knot k's Jacobian that can be nonzero, from the
        Jacobian at random points (structural zeros stay exactly zero)."""
        rows = self.knot(k)
        rng = np.random.default_rng(0)
        mask = np.zeros((rows.num_rows[0], KNOT_SIZE), dtype=bool)
        for _ in range(3):
            mask |= rows.evaluate(rng.uniform(-1, 1, (1, KNOT_SIZE)), True)[1][0] != 0.0
        return [(int(i), int(j)) for i, j in zip(*np.nonzero(mask))]
