"""Named columns and rows of one knot's nonlinear block (knot.py, knot_jacobian.py).

Columns are positions in a knot's KNOT_SIZE variables, derived from variables.SLICES:
the object's position p (x, y), angle theta, their rates and accelerations; per
finger i (arrays indexed by i) its two joints' q, qd, qdd, tau, and its lambda_n,
lambda_t and slack gamma. Rows: the object's force (2) and moment (1) rows, the hand's
8 rows (finger-major), then each finger's contact rows (PINNED_ROWS or FREE_ROWS), at
the offsets named below inside that finger's block.
"""

from __future__ import annotations

import numpy as np

from trajectotree.cito.variables import SLICES
from trajectotree.scene.plant import NUM_FINGERS, NUM_HAND_JOINTS

_F = np.arange(NUM_FINGERS)
TWO = np.arange(2)


def _planar(name: str) -> tuple[slice, int]:
    """(columns of the (x, y) part, column of the angle) of a 3-wide object group."""
    start = SLICES[name].start
    return slice(start, start + 2), start + 2


def _per_joint(name: str) -> np.ndarray:
    """(4, 2) columns of a finger-major joint group."""
    return SLICES[name].start + 2 * _F[:, None] + TWO


COL_P, COL_TH = _planar("x")  # object position, angle
COL_PD, COL_THD = _planar("xd")  # their rates
COL_PDD, COL_THDD = _planar("xdd")  # their accelerations
COL_P_IDX = np.arange(COL_P.start, COL_P.stop)  # the same columns as index arrays
COL_PD_IDX = np.arange(COL_PD.start, COL_PD.stop)
COL_Q, COL_QD, COL_QDD, COL_TAU = (_per_joint(n) for n in ("q", "qd", "qdd", "tau"))
COL_LN, COL_LT, COL_G = (SLICES[n].start + _F for n in ("lambda_n", "lambda_t", "slack"))

ROW_FORCE, ROW_MOMENT = slice(0, 2), 2  # object: m p_dd - sum f - m g, I theta_dd - sum moments
ROW_HAND = slice(3, 3 + NUM_HAND_JOINTS)  # hand: M q_dd - tau - tau_g + J_C^T f
ROW_HAND_IDX = ROW_HAND.start + 2 * _F[:, None] + TWO  # (4, 2) the hand rows per finger and joint
NUM_BODY_ROWS = ROW_HAND.stop
PINNED_ROWS, FREE_ROWS = 4, 6
PIN_MINUS, PIN_PLUS = 0, 2  # pinned: gamma - e (x, y), gamma + e (x, y)
FREE_PHI, FREE_COMP = 0, 1  # free: phi - r, gamma - (phi - r) lambda_n,
FREE_SLIP = 2  # then gamma - v_a lambda_n at FREE_SLIP + 2a, gamma + v_a lambda_n one after
