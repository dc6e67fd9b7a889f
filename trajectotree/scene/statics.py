"""Finger statics shared by the search and the controllers: the rows that keep planar contact
forces lambda = (lambda_n, lambda_t) per finger inside their friction cones, the wrench those forces
apply to the object, and the joint torques they cost the motors (through the fingertip Jacobians)."""

from __future__ import annotations

import numpy as np


def perp(v) -> np.ndarray:
    """z x v for planar vectors (..., 2)."""
    out = np.empty_like(v)
    out[..., 0], out[..., 1] = -v[..., 1], v[..., 0]
    return out


def grasp_matrix_W(p_WC, n_W) -> np.ndarray:
    """(3, 2k): the wrench in W, about the object's centroid, of contact forces -lambda_n n +
    lambda_t t (t = z x n, the outward normal n) at contacts p_WC (k, 2) relative to the centroid."""
    t_W = perp(n_W)
    G = np.empty((3, 2 * len(p_WC)))
    G[:2, 0::2], G[:2, 1::2] = -n_W.T, t_W.T
    G[2, 0::2] = p_WC[:, 0] * -n_W[:, 1] + p_WC[:, 1] * n_W[:, 0]
    G[2, 1::2] = p_WC[:, 0] * t_W[:, 1] - p_WC[:, 1] * t_W[:, 0]
    return G


def cone_rows(mu: float, num_fingers: int) -> np.ndarray:
    """(2F, 2F): lambda_t - mu lambda_n <= 0 and -lambda_t - mu lambda_n <= 0 for each finger."""
    cone = np.zeros((2 * num_fingers, 2 * num_fingers))
    for i in range(num_fingers):
        cone[2 * i, 2 * i : 2 * i + 2] = (-mu, 1.0)
        cone[2 * i + 1, 2 * i : 2 * i + 2] = (-mu, -1.0)
    return cone


def torque_rows(
    J_WF, n_W, t_W, tip_radius: float, rest, tau_max
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The joint torques that the finger forces lambda add to `rest` (F, 2: springs and
    gravity), bounded by the motors' tau_max (F, 2): (A (2F, 2F) block-diagonal, lower (2F,),
    upper (2F,)) for GraspForceQp.solve, and the most normal force (F,) each finger can push
    with without tangential force. The force -lambda_n n + lambda_t t acts tip_radius from the
    sphere centre along -n: its lever adds -tip_radius lambda_t to both joints. The bounds
    are widened to admit lambda = 0 where `rest` alone is beyond the motors, so that the QP
    stays feasible (the plant clips what is left)."""
    num_fingers = len(J_WF)
    A = np.zeros((2 * num_fingers, 2 * num_fingers))
    Jt = np.swapaxes(J_WF, 1, 2)  # (F, 2 joints, 2)
    normal = np.einsum("fji,fi->fj", Jt, -n_W)
    tangential = np.einsum("fji,fi->fj", Jt, t_W) - tip_radius
    for i in range(num_fingers):
        A[2 * i : 2 * i + 2, 2 * i] = normal[i]
        A[2 * i : 2 * i + 2, 2 * i + 1] = tangential[i]
    lower = np.minimum(-tau_max - rest, 0.0).ravel()
    upper = np.maximum(tau_max - rest, 0.0).ravel()
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(
            normal > 0, upper.reshape(-1, 2) / normal, np.where(normal < 0, lower.reshape(-1, 2) / normal, np.inf)
        )
    return A, lower, upper, room.min(axis=1)
