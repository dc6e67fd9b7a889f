"""Rolling contacts in space (search.rolled_stances, for the search in space of trajectotree.search.space_tree).

The plan keeps a holding fingertip's contact point fixed on the cube, but a fingertip sphere of radius r that
sticks to a face rolls along it as the finger's last link turns relative to the cube: without slip, its centre
moves in the cube's frame B at r (w_rel x n_B), w_rel the link's angular velocity relative to the cube and n_B the
face's outward normal, so over a transition by r (phi x n_B), phi the rotation vector of the link's turn relative
to the cube. Seed-0 SO(3) goal 25, executed open loop: its fingertips had rolled 8.1, 6.6, 7.7 and 11.3 mm off
their planned points after 3 s (this prediction from the plan's knots: 8.6, 7.4, 7.8, 11.4 mm), and the three-finger
stance at the contacts they had rolled to needed 3.0 N m at a joint to hold the cube (0.183 N m at the planned
ones; the motors give 0.396): the grasp QP hit a motor limit and the cube turned 17 deg off its plan. As the
plane's StanceChecks.rolled (trajectotree.search.stance), the search in space therefore checks each stance at the
contacts its fingertips will have rolled to since they landed, predicted node to node from the nodes' joint angles.
"""

from __future__ import annotations

import numpy as np

from trajectotree.geometry import box_outward_directions, box_signed_distances, so3_exp, so3_log
from trajectotree.scene.kinematics import SerialFinger

# m, the gap the swing check lifts a moving fingertip to off the cube between its ends: CITO's mid-swing clearance in
# space (cito.spatial.SWITCH_CLEARANCE); the executed swing travels 8 mm up (controller.grasp.swing_lift)
SWING_LIFT = 0.01
SWING_SAMPLES = 5  # interior points of a swing checked: one every 3.3 deg of a 20 deg segment, 5 mm of a 3 cm move
NEWTON_STEPS = 3  # Gauss-Newton steps that move a fingertip centre onto its rolled point (a few mm: < 1 um after 3)


def chain(finger: SerialFinger, q) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(c' (..., n, 3), a' (..., n, 3), p_WF (..., 3), R (..., 3, 3)): SerialFinger.frames' joint points, axes and
    fingertip centre, and the last link's rotation in W relative to its own at q = 0, at joint angles q (..., n), by
    composing the joints' rigid turns as matrices (the same values to 1e-15 m, a third of frames' time: the rolled
    stances' IK runs it thousands of times a search)."""
    q = np.asarray(q, dtype=float)
    turns = so3_exp(q[..., :, None] * finger.a_W)  # (..., n, 3, 3), joint j's turn about its axis at q = 0
    R = np.broadcast_to(np.eye(3), q.shape[:-1] + (3, 3))
    t = np.zeros(q.shape[:-1] + (3,))
    points, axes = [], []
    for j, (c, a) in enumerate(zip(finger.p_W_joint, finger.a_W)):
        points.append(R @ c + t)
        axes.append(R @ a)
        t = t + R @ c - np.einsum("...ij,...jk,k->...i", R, turns[..., j, :, :], c)  # then p -> c + turn (p - c)
        R = R @ turns[..., j, :, :]
    return np.stack(points, axis=-2), np.stack(axes, axis=-2), R @ finger.p_W_tip0 + t, R


def chain_jacobian(points, axes, p_WQ) -> np.ndarray:
    """(..., 3, n) d p_WQ / d q of the point p_WQ (..., 3) on the last link, for chain's points and axes."""
    return np.swapaxes(np.cross(axes, np.asarray(p_WQ)[..., None, :] - points), -1, -2)


def link_rotations(finger: SerialFinger, q) -> np.ndarray:
    """(..., 3, 3) the last link's rotation in W relative to its own at q = 0, at joint angles q (..., n): the
    product of exponentials of the joints' axes at q = 0 (SerialFinger's form)."""
    return chain(finger, q)[3]


def rolled_step(finger: SerialFinger, q0, q1, R_WB0, R_WB1, n_B, tip_radius: float) -> np.ndarray:
    """(3,) m in B: how far the sticking fingertip sphere of `finger` on the face of outward normal n_B (3,) rolls
    along it while the joints go from q0 to q1 (n,) and the cube's orientation from R_WB0 to R_WB1 (3, 3): r (phi x
    n_B), phi the link's turn relative to the cube (its spin about n_B rolls nothing)."""
    A0 = R_WB0.T @ link_rotations(finger, q0)
    A1 = R_WB1.T @ link_rotations(finger, q1)
    return tip_radius * np.cross(so3_log(A1 @ A0.T), n_B)


def on_face(p_BC, n_B, half, gap: float) -> np.ndarray:
    """(k,) bool: each contact p_BC (k, 3) on its face (outward normal n_B (k, 3), one of the box's axes) at least
    `gap` m short of the face's edges, for a box of half-sizes `half` (3,) m."""
    inside = np.abs(np.asarray(p_BC, dtype=float)) <= np.asarray(half, dtype=float) - gap
    return np.all(inside | (np.abs(np.asarray(n_B)) > 0.5), axis=-1)


def moved_joints(finger: SerialFinger, q, p_WF) -> np.ndarray:
    """(..., n) the joint angles near q (..., n) that put the fingertip centre at p_WF (..., 3) m (Gauss-Newton from
    q, for targets a few mm off; the joint limits not applied: a rolled fingertip is where the cube takes it)."""
    q = np.array(q, dtype=float)
    for _ in range(NEWTON_STEPS):
        points, axes, tip, _ = chain(finger, q)
        q += (np.linalg.pinv(chain_jacobian(points, axes, tip)) @ (np.asarray(p_WF) - tip)[..., None])[..., 0]
    return q


def lifted_swing(a_B, b_B, half, tip_radius: float, samples: int = SWING_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """(s (samples,), p_B (samples, 3) m): the interior points at fractions s of a fingertip centre's swing from a_B
    to b_B (3,) in B over a box of half-sizes `half` (3,) m: the straight line, pushed off the box to at least
    tip_radius + SWING_LIFT of gap (the path a lifted fingertip takes, without its rise and descent at the ends)."""
    s = np.arange(1, samples + 1) / (samples + 1)
    p = (1.0 - s)[:, None] * np.asarray(a_B, dtype=float) + s[:, None] * np.asarray(b_B, dtype=float)
    short = np.maximum(tip_radius + SWING_LIFT - box_signed_distances(half, p), 0.0)
    return s, p + short[:, None] * box_outward_directions(half, p)
