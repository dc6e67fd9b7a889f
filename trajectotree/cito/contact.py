"""A smooth signed distance to the object (any convex polygon) and its contact frame, for IPOPT.

The exact distance (`geometry.ConvexPolygon.signed_distance`) has a kink on the
polygon's corner bisectors and a non-smooth normal, which IPOPT cannot use. We use the
log-sum-exp of the V face distances d_j = n_j . p - h_j (the polygon's outward normals
n_j and offsets h_j, geometry.ConvexPolygon.normals and .offsets),

    phi(p_B) = max_j d_j + (1/k) log sum_j exp(k (d_j - max_j d_j)),

with sharpness k (CitoConfig.sdf_sharpness, 1/m). It is never below the max of the
face distances, exceeds it by (1/k) log(1 + sum_{j != face} exp(-k gap_j)) (gap_j:
how much smaller the other face distances are), so it is exact on a face away from
the corners, and over-estimates the max of the face distances near a corner by up to
log(2)/k (0.7 mm for k = 1000; a fingertip rounding a corner may sink that deep; log(V)/k
where all faces are about as near, the centre of a small polygon only). Beyond a corner
(where the corner itself is the nearest point) the max of the face distances is below the
exact distance |p - corner|, by up to a factor cos(exterior angle / 2) on the bisector
(0.71 for the box, 0.5 for the triangle, 0.87 for the hexagon). Its gradient
is a convex combination of the face normals (softmax weights), so
n_B = grad phi / |grad phi| is smooth and equals the face normal away from the
corners. Tests compare it with the exact distance. Vectorized over points (P, 2).
"""

from __future__ import annotations

import numpy as np


def smooth_distance(p_B: np.ndarray, normals: np.ndarray, offsets: np.ndarray, sharpness: float):
    """(phi (P,), grad (P, 2), hess (P, 2, 2)) of the smooth distance at points p_B (P, 2) to the
    polygon of outward unit face normals (V, 2) and offsets (V,) m (n_j . p = h_j on face j)."""
    d = p_B @ normals.T - offsets  # (P, V) face distances
    dmax = d.max(axis=1, keepdims=True)
    e = np.exp(sharpness * (d - dmax))
    s = e.sum(axis=1, keepdims=True)
    w = e / s  # softmax weights
    phi = dmax[:, 0] + np.log(s[:, 0]) / sharpness
    grad = w @ normals
    # hess = k (N^T diag(w) N - grad grad^T)
    hess = sharpness * (np.einsum("pj,ja,jb->pab", w, normals, normals) - grad[:, :, None] * grad[:, None, :])
    return phi, grad, hess


def smooth_normal(grad: np.ndarray, hess: np.ndarray):
    """(n_B (P, 2), dn_B/dp_B (P, 2, 2)): the unit normal grad/|grad| and its Jacobian."""
    norm = np.linalg.norm(grad, axis=1)
    n = grad / norm[:, None]
    proj = np.eye(2)[None] - n[:, :, None] * n[:, None, :]
    return n, proj @ hess / norm[:, None, None]
