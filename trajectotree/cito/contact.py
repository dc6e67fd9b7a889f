"""A smooth signed distance to the box and its contact frame, for IPOPT.

The exact distance (`geometry.ConvexPolygon.signed_distance`) has a kink on the
box's diagonals and a non-smooth normal, which IPOPT cannot use. We use the
log-sum-exp of the four face distances d_j = n_j . p - h_j,

    phi(p_B) = max_j d_j + (1/k) log sum_j exp(k (d_j - max_j d_j)),

with sharpness k (CitoConfig.sdf_sharpness, 1/m). It is never below the max of the
face distances, exceeds it by (1/k) log(1 + sum_{j != face} exp(-k gap_j)) (gap_j:
how much smaller the other face distances are), so it is exact on a face away from
the corners, and over-estimates the exact distance near a corner by up to log(2)/k
(0.7 mm for k = 1000; a fingertip rounding a corner may sink that deep). Its gradient
is a convex combination of the face normals (softmax weights), so
n_B = grad phi / |grad phi| is smooth and equals the face normal away from the
corners. Tests compare it with the exact distance. Vectorized over points (P, 2).
"""

from __future__ import annotations

import numpy as np

# Outward face normals of the box in B: right, top, left, bottom.
FACE_NORMALS = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])


def face_offsets(width: float, height: float) -> np.ndarray:
    return np.array([width / 2, height / 2, width / 2, height / 2])


def smooth_distance(p_B: np.ndarray, offsets: np.ndarray, sharpness: float):
    """(phi (P,), grad (P, 2), hess (P, 2, 2)) of the smooth box distance at points p_B (P, 2)."""
    d = p_B @ FACE_NORMALS.T - offsets            # (P, 4) face distances
    dmax = d.max(axis=1, keepdims=True)
    e = np.exp(sharpness * (d - dmax))
    s = e.sum(axis=1, keepdims=True)
    w = e / s                                     # softmax weights
    phi = dmax[:, 0] + np.log(s[:, 0]) / sharpness
    grad = w @ FACE_NORMALS
    # hess = k (N^T diag(w) N - grad grad^T)
    hess = sharpness * (np.einsum("pj,ja,jb->pab", w, FACE_NORMALS, FACE_NORMALS) - grad[:, :, None] * grad[:, None, :])
    return phi, grad, hess


def smooth_normal(grad: np.ndarray, hess: np.ndarray):
    """(n_B (P, 2), dn_B/dp_B (P, 2, 2)): the unit normal grad/|grad| and its Jacobian."""
    norm = np.linalg.norm(grad, axis=1)
    n = grad / norm[:, None]
    proj = np.eye(2)[None] - n[:, :, None] * n[:, None, :]
    return n, proj @ hess / norm[:, None, None]
