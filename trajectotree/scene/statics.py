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


# -- in space ------------------------------------------------------------------------------------
# A contact force in space: f = -lambda_n n + lambda_1 t1 + lambda_2 t2 on the object, n the outward
# normal, (t1, t2) tangents with t1 x t2 = n; its friction cone linearized as a pyramid of m edges
# -n + mu (cos a_e t1 + sin a_e t2), a_e = 2 pi e / m (inscribed: a force on an edge is in the cone).


def tangent_basis(n_W) -> tuple[np.ndarray, np.ndarray]:
    """(t1, t2), each (..., 3): unit tangents of the unit normals n_W (..., 3), t1 x t2 = n; t1 is
    the normal's cross product with the world axis it is least aligned with (no singular direction)."""
    n = np.asarray(n_W, dtype=float)
    helper = np.eye(3)[np.argmin(np.abs(n), axis=-1)]
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(n, t1)


def pyramid_edges(n_W, mu: float, num_edges: int) -> np.ndarray:
    """(k, m, 3): the m edges of each contact's friction pyramid (normal component 1) for normals (k, 3)."""
    n = np.atleast_2d(np.asarray(n_W, dtype=float))
    t1, t2 = tangent_basis(n)
    a = 2 * np.pi * np.arange(num_edges) / num_edges
    return -n[:, None, :] + mu * (np.cos(a)[None, :, None] * t1[:, None, :] + np.sin(a)[None, :, None] * t2[:, None, :])


def wrenches_W(p_WC, f_W) -> np.ndarray:
    """(..., 6) [f; p x f]: the wrenches about the object's centre of forces f_W (..., 3) at p_WC
    (..., 3) relative to that centre (W)."""
    f = np.asarray(f_W, dtype=float)
    return np.concatenate([f, np.cross(np.broadcast_to(p_WC, f.shape), f)], axis=-1)


def grasp_matrix_3d_W(p_WC, n_W) -> np.ndarray:
    """(6, 3k): the wrench in W about the object's centre of the contact forces (lambda_n,
    lambda_1, lambda_2) per contact at p_WC (k, 3) relative to that centre, normals n_W (k, 3)."""
    p, n = np.atleast_2d(p_WC), np.atleast_2d(n_W)
    t1, t2 = tangent_basis(n)
    directions = np.stack([-n, t1, t2], axis=1)  # (k, 3, 3): a unit force along each column's direction
    return wrenches_W(p[:, None, :], directions).reshape(-1, 6).T


def edge_wrenches_W(p_WC, n_W, mu: float, num_edges: int) -> np.ndarray:
    """(6, k m): the wrenches of each contact's pyramid edges, contact-major."""
    edges = pyramid_edges(n_W, mu, num_edges)
    return wrenches_W(np.atleast_2d(p_WC)[:, None, :], edges).reshape(-1, 6).T


def finger_torques(J_WC, f_W, tau_gravity) -> np.ndarray:
    """(F, n) N m: the joint torques a finger's motors give to push with f_W (F, 3) on the object at
    its contact point (J_WC (F, 3, n), the point's translational Jacobian) while holding its own
    weight (tau_gravity (F, n)): tau = tau_gravity + J^T f."""
    return np.asarray(tau_gravity) + np.einsum("fcj,fc->fj", J_WC, f_W)


def cone_rows_3d(mu: float, num_fingers: int, num_facets: int) -> np.ndarray:
    """(F m, 3F): the pyramid inscribed in each contact's friction cone, as rows <= 0 on lambda = (lambda_n,
    lambda_1, lambda_2) per finger: cos b lambda_1 + sin b lambda_2 - mu cos(pi / m) lambda_n <= 0 for each facet,
    b = 2 pi (e + 1/2) / m. The facets join the edges of pyramid_edges, so both describe one pyramid (the planar
    cone_rows is its m = 2 section)."""
    b = 2 * np.pi * (np.arange(num_facets) + 0.5) / num_facets
    facet = np.column_stack([np.full(num_facets, -mu * np.cos(np.pi / num_facets)), np.cos(b), np.sin(b)])
    return np.kron(np.eye(num_fingers), facet)


def contact_torque_rows(J_WC, directions, rest, tau_max) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint torques that contact forces f_i = directions_i lambda_i add to `rest` (F, n: the fingers' weight and
    springs), bounded by the motors' tau_max (F, n), for J_WC (F, 3, n) the contact points' translational Jacobians
    and directions (F, 3, k) each force component's unit direction: (A (F n, F k) block-diagonal, lower (F n,),
    upper (F n,)), lower <= A lambda <= upper. As the planar torque_rows (whose Jacobian is the fingertip centre's,
    its lever added by hand), the bounds are widened to admit lambda = 0 where `rest` alone is beyond the motors."""
    blocks = np.einsum("fcj,fck->fjk", J_WC, directions)  # (F, n, k): J_C^T D
    A = np.zeros((blocks.shape[0] * blocks.shape[1], blocks.shape[0] * blocks.shape[2]))
    for i, block in enumerate(blocks):
        A[i * block.shape[0] : (i + 1) * block.shape[0], i * block.shape[1] : (i + 1) * block.shape[1]] = block
    rest, tau_max = np.asarray(rest, dtype=float), np.asarray(tau_max, dtype=float)
    return A, np.minimum(-tau_max - rest, 0.0).ravel(), np.maximum(tau_max - rest, 0.0).ravel()
