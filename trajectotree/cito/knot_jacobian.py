"""The analytic Jacobian of the knot rows (knot.py), vectorized over knots and fingers,
addressed through the named columns and rows of layout.py.

Per finger, everything depends on the object's position p and angle theta and on the
finger's joints q through p_BF = R^T (p_WF - p) and the contact normal n_W; `_partials`
computes those chain-rule factors once, then each block of rows writes its entries.
tests/test_cito_model.py checks the result against central differences of the values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectotree.cito.layout import (
    COL_P,
    COL_P_IDX,
    COL_PD_IDX,
    COL_PDD,
    COL_TH,
    COL_THD,
    COL_THDD,
    FREE_COMP,
    FREE_PHI,
    FREE_SLIP,
    PIN_MINUS,
    PIN_PLUS,
    ROW_FORCE,
    ROW_MOMENT,
    TWO,
)
from trajectotree.scene.kinematics import K90

_I2 = np.eye(2)
# Free-finger slip rows FREE_SLIP + s, s = 0..3: gamma + SLIP_SIGN[s] v_a lambda_n, a = SLIP_A[s].
SLIP_A, SLIP_SIGN = np.array([0, 0, 1, 1]), np.array([-1.0, 1.0, -1.0, 1.0])


def _put(jac: np.ndarray, rows, key: str, where, value) -> None:
    """jac[where()] = value, as numpy's fancy assignment with the index arrays where() returns,
    through flat positions computed on the first call per KnotRows, block and shape (the
    index arithmetic and 3-index scatter cost more than the values at 13 knots)."""
    cache = rows.index_cache
    idx = cache.get((key, jac.shape))
    if idx is None:
        idx = cache[(key, jac.shape)] = np.ravel_multi_index(np.broadcast_arrays(*where()), jac.shape)
    jac.reshape(-1)[idx] = value


@dataclass(frozen=True)
class _Partials:
    """Derivatives of each finger's p_BF, n_W, f_W and arm (K, 4, 2[, 2]) with respect to
    the object's p (2 columns), theta, and the finger's q (2 columns)."""

    dpB_dth: np.ndarray
    dpB_dq: np.ndarray
    df_dp: np.ndarray
    df_dth: np.ndarray
    df_dq: np.ndarray
    darm_dp: np.ndarray
    darm_dth: np.ndarray
    darm_dq: np.ndarray


def _partials(rows, Z: np.ndarray, kin) -> _Partials:
    L = rows.layout
    r = rows.body.radius
    ln, lt = Z[:, L.block.slices["lambda_n"]], Z[:, L.block.slices["lambda_t"]]
    R, RT, J, n_W = kin.R, kin.RT, kin.J, kin.n_W
    # Derivatives of p_BF = R^T (p_WF - p): wrt p (-R^T), theta (-K p_BF), q_i (R^T J_i).
    dpB_dth = -(kin.p_BF @ K90.T)
    dpB_dq = RT[:, None] @ J
    dn_s = np.where(rows.pinned[..., None][..., None], 0.0, kin.dn_s)  # pinned normals are fixed in B
    RdnB = R[:, None] @ dn_s  # R dn_B/dp_B
    dnW_dp = -(RdnB @ RT[:, None])
    dnW_dth = n_W @ K90.T + np.einsum("kiab,kib->kia", RdnB, dpB_dth)
    dnW_dq = RdnB @ dpB_dq
    A = -ln[..., None, None] * _I2 + lt[..., None, None] * K90  # f_W = A n_W
    return _Partials(
        dpB_dth=dpB_dth,
        dpB_dq=dpB_dq,
        df_dp=A @ dnW_dp,
        df_dth=np.einsum("kiab,kib->kia", A, dnW_dth),
        df_dq=A @ dnW_dq,
        darm_dp=-_I2 - r * dnW_dp,
        darm_dth=-r * dnW_dth,
        darm_dq=J - r * dnW_dq,
    )


def knot_jacobian(rows, Z: np.ndarray, kin) -> np.ndarray:
    """(K, R, knot size): the Jacobian of `rows.evaluate`'s values at knots Z, with
    kin = rows.kinematics(Z)."""
    L = rows.layout
    jac = np.zeros((Z.shape[0], int(rows.num_rows.max()), L.block.size))
    d = _partials(rows, Z, kin)
    _object_rows(jac, rows, kin, d)
    _hand_rows(jac, rows, Z, kin, d)
    _pinned_rows(jac, rows, kin)
    _free_rows(jac, rows, Z, kin, d)
    return jac


def _object_rows(jac, rows, kin, d: _Partials) -> None:
    L = rows.layout
    b, nK = rows.body, jac.shape[0]
    n_W, t_W, f_W, arm = kin.n_W, kin.t_W, kin.f_W, kin.arm
    # Translation rows.
    jac[:, ROW_FORCE, COL_P] = -d.df_dp.sum(1)
    jac[:, ROW_FORCE, COL_TH] = -d.df_dth.sum(1)
    jac[:, ROW_FORCE, COL_PDD] = b.mass * _I2
    jac[:, ROW_FORCE, L.block.slices["q"]] = -d.df_dq.transpose(0, 2, 1, 3).reshape(nK, 2, -1)
    jac[:, ROW_FORCE, L.col_ln] = n_W.transpose(0, 2, 1)
    jac[:, ROW_FORCE, L.col_lt] = -t_W.transpose(0, 2, 1)
    # Rotation row: d cross(arm, f) = -(K f).d arm + (K arm).d f.
    Kf, Ka = f_W @ K90.T, arm @ K90.T
    jac[:, ROW_MOMENT, COL_P] = np.einsum("kia,kiab->kb", Kf, d.darm_dp) - np.einsum("kia,kiab->kb", Ka, d.df_dp)
    jac[:, ROW_MOMENT, COL_TH] = np.sum(Kf * d.darm_dth, axis=(1, 2)) - np.sum(Ka * d.df_dth, axis=(1, 2))
    jac[:, ROW_MOMENT, COL_THDD] = b.inertia
    jac[:, ROW_MOMENT, L.block.slices["q"]] = (
        np.einsum("kia,kiab->kib", Kf, d.darm_dq) - np.einsum("kia,kiab->kib", Ka, d.df_dq)
    ).reshape(nK, -1)
    jac[:, ROW_MOMENT, L.col_ln] = np.sum(Ka * n_W, axis=2)
    jac[:, ROW_MOMENT, L.col_lt] = -np.sum(Ka * t_W, axis=2)


def _hand_rows(jac, rows, Z, kin, d: _Partials) -> None:
    """d(J^T f)/dq = [[-(r1+r2).f, -r2.f], [-r2.f, -r2.f]] + J^T df/dq, plus M, tau, gravity."""
    L = rows.layout
    hand, r, nK = rows.body.hand, rows.body.radius, jac.shape[0]
    q, qdd = Z[:, L.block.slices["q"]], Z[:, L.block.slices["qdd"]].reshape(nK, L.num_fingers, 2)
    JT = kin.J.swapaxes(-1, -2)
    a12, a2 = np.sum((kin.r1 + kin.r2) * kin.f_W, -1), np.sum(kin.r2 * kin.f_W, -1)
    H_q = JT @ d.df_dq - hand.gravity_derivatives(q)
    H_q[..., 0, 0] -= a12
    H_q[..., 0, 1] -= a2
    H_q[..., 1, :] -= a2[..., None]
    H_q[..., :, 1] += np.einsum("kiab,kib->kia", hand.mass_derivatives(q), qdd)
    kk = np.arange(nK)[:, None, None]
    rows_h = L.row_hand_idx[None, :, :, None]
    _put(jac, rows, "hand_q", lambda: (kk[..., None], rows_h, L.col_q[None, :, None, :]), H_q)
    _put(jac, rows, "hand_qdd", lambda: (kk[..., None], rows_h, L.col_qdd[None, :, None, :]), hand.mass_matrices(q))
    _put(jac, rows, "hand_tau", lambda: (kk[..., None], rows_h, L.col_tau[None, :, None, :]), -_I2)
    jac[:, L.row_hand, COL_P] = (JT @ d.df_dp).reshape(nK, 2 * L.num_fingers, 2)
    jac[:, L.row_hand, COL_TH] = np.einsum("kiab,kib->kia", JT, d.df_dth).reshape(nK, -1)
    _put(
        jac,
        rows,
        "hand_ln",
        lambda: (kk, L.row_hand_idx[None], L.col_ln[None, :, None]),
        -np.einsum("kiab,kib->kia", JT, kin.n_W),
    )
    _put(
        jac,
        rows,
        "hand_lt",
        lambda: (kk, L.row_hand_idx[None], L.col_lt[None, :, None]),
        np.einsum("kiab,kib->kia", JT, kin.t_W) - r,
    )


def _pinned_rows(jac, rows, kin) -> None:
    """gamma -/+ e, e = p_WF - p - R c_B."""
    L = rows.layout
    kP, iP = rows.kP, rows.iP
    rp = rows.row_start[kP, iP]
    de_dth = -(rows.c_B[kP, iP][:, None, :] @ kin.RT[kP])[:, 0] @ K90.T
    kP2, kP3 = kP[:, None], kP[:, None, None]
    J = kin.J[kP, iP]
    for sign, off in ((-1.0, PIN_MINUS), (1.0, PIN_PLUS)):
        rws = rp[:, None] + off + TWO  # (nP, 2)
        _put(jac, rows, f"pin_g{off}", lambda rws=rws: (kP2, rws, L.col_g[iP, None]), 1.0)
        _put(jac, rows, f"pin_q{off}", lambda rws=rws: (kP3, rws[:, :, None], L.col_q[iP][:, None, :]), sign * J)
        _put(jac, rows, f"pin_p{off}", lambda rws=rws: (kP3, rws[:, :, None], COL_P_IDX), -sign * _I2)
        _put(jac, rows, f"pin_th{off}", lambda rws=rws: (kP2, rws, COL_TH), sign * de_dth)


def _free_rows(jac, rows, Z, kin, d: _Partials) -> None:
    """phi - r, gamma - (phi - r) lambda_n, gamma -/+ v_a lambda_n."""
    L = rows.layout
    nK = Z.shape[0]
    kF, iF = rows.kF, rows.iF
    rf = rows.row_start[kF, iF]
    lnF = Z[:, L.block.slices["lambda_n"]][kF, iF]
    thd, qd = Z[:, COL_THD], Z[:, L.block.slices["qd"]].reshape(nK, L.num_fingers, 2)
    gF = kin.grad[kF, iF]
    dphi_dp = -(gF[:, None, :] @ kin.RT[kF])[:, 0]
    dphi_dth = np.sum(gF * d.dpB_dth[kF, iF], 1)
    dphi_dq = np.einsum("na,naj->nj", gF, d.dpB_dq[kF, iF])
    kF2 = kF[:, None]
    colqF = L.col_q[iF]
    for off, scale in ((FREE_PHI, None), (FREE_COMP, -lnF)):
        row = rf + off
        _put(
            jac,
            rows,
            f"free_p{off}",
            lambda row=row: (kF2, row[:, None], COL_P_IDX),
            dphi_dp if scale is None else scale[:, None] * dphi_dp,
        )
        _put(
            jac,
            rows,
            f"free_th{off}",
            lambda row=row: (kF, row, COL_TH),
            dphi_dth if scale is None else scale * dphi_dth,
        )
        _put(
            jac,
            rows,
            f"free_q{off}",
            lambda row=row: (kF2, row[:, None], colqF),
            dphi_dq if scale is None else scale[:, None] * dphi_dq,
        )
    _put(jac, rows, "free_comp_ln", lambda: (kF, rf + FREE_COMP, L.col_ln[iF]), -kin.phi_tip[kF, iF])
    _put(jac, rows, "free_comp_g", lambda: (kF, rf + FREE_COMP, L.col_g[iF]), 1.0)
    qdF, r1F, r2F, JF = qd[kF, iF], kin.r1[kF, iF], kin.r2[kF, iF], kin.J[kF, iF]
    dv_dq = -np.stack([(r1F + r2F) * qdF[:, :1] + r2F * qdF[:, 1:], r2F * (qdF[:, :1] + qdF[:, 1:])], axis=2)
    dv_dq -= thd[kF, None, None] * (K90 @ JF)  # (nF, comp, joint)
    dv_dthd = -(kin.rel[kF, iF] @ K90.T)
    thdK = thd[kF, None, None] * K90  # dv/dp
    # The four slip rows at once, s = 0..3: row FREE_SLIP + s, component a = SLIP_A[s], sign SLIP_SIGN[s].
    vF = kin.v[kF, iF]
    sl = SLIP_SIGN[:, None] * lnF  # (4, nF)
    rws = rf + (FREE_SLIP + np.arange(4))[:, None]
    _put(jac, rows, "slip_g", lambda: (kF, rws, L.col_g[iF]), 1.0)
    _put(jac, rows, "slip_ln", lambda: (kF, rws, L.col_ln[iF]), SLIP_SIGN[:, None] * vF.T[SLIP_A])
    _put(
        jac, rows, "slip_qd", lambda: (kF2, rws[..., None], L.col_qd[iF]), sl[..., None] * JF[:, SLIP_A].swapaxes(0, 1)
    )
    _put(jac, rows, "slip_pd", lambda: (kF, rws, COL_PD_IDX[SLIP_A][:, None]), -sl)
    _put(jac, rows, "slip_thd", lambda: (kF, rws, COL_THD), sl * dv_dthd.T[SLIP_A])
    _put(jac, rows, "slip_q", lambda: (kF2, rws[..., None], colqF), sl[..., None] * dv_dq[:, SLIP_A].swapaxes(0, 1))
    _put(jac, rows, "slip_p", lambda: (kF2, rws[..., None], COL_P_IDX), sl[..., None] * thdK[:, SLIP_A].swapaxes(0, 1))
