"""Named columns and rows of one knot's nonlinear block (knot.py, knot_jacobian.py).

Columns are positions in a knot's variables (variables.knot_block): the object's position
p (x, y), angle theta, their rates and accelerations (module constants: they come first,
whatever the hand); per finger i (arrays indexed by i, `knot_layout(F)` for F fingers) its
two joints' q, qd, qdd, tau, and its lambda_n, lambda_t and slack gamma. Rows: the object's
force (2) and moment (1) rows, the hand's 2F rows (finger-major), then each finger's contact
rows (PINNED_ROWS or FREE_ROWS), at the offsets named below inside that finger's block.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from trajectotree.cito.variables import KnotBlock, knot_block

TWO = np.arange(2)
_OBJECT = knot_block(0).slices  # the object's groups come first: their columns do not depend on the hand


def _planar(name: str) -> tuple[slice, int]:
    """(columns of the (x, y) part, column of the angle) of a 3-wide object group."""
    start = _OBJECT[name].start
    return slice(start, start + 2), start + 2


COL_P, COL_TH = _planar("x")  # object position, angle
COL_PD, COL_THD = _planar("xd")  # their rates
COL_PDD, COL_THDD = _planar("xdd")  # their accelerations
COL_P_IDX = np.arange(COL_P.start, COL_P.stop)  # the same columns as index arrays
COL_PD_IDX = np.arange(COL_PD.start, COL_PD.stop)

ROW_FORCE, ROW_MOMENT = slice(0, 2), 2  # object: m p_dd - sum f - m g, I theta_dd - sum moments
PINNED_ROWS, FREE_ROWS = 4, 6
PIN_MINUS, PIN_PLUS = 0, 2  # pinned: gamma - e (x, y), gamma + e (x, y)
FREE_PHI, FREE_COMP = 0, 1  # free: phi - r, gamma - (phi - r) lambda_n,
FREE_SLIP = 2  # then gamma - v_a lambda_n at FREE_SLIP + 2a, gamma + v_a lambda_n one after


@dataclass(frozen=True)
class KnotLayout:
    """The hand's columns and rows of one knot's block, for a hand of F fingers."""

    block: KnotBlock  # the knot's variables (slices, size)
    col_q: np.ndarray  # (F, 2) columns of each finger's joint angles
    col_qd: np.ndarray  # (F, 2) their rates
    col_qdd: np.ndarray  # (F, 2) their accelerations
    col_tau: np.ndarray  # (F, 2) the joint torques
    col_ln: np.ndarray  # (F,) lambda_n
    col_lt: np.ndarray  # (F,) lambda_t
    col_g: np.ndarray  # (F,) slack gamma
    row_hand: slice  # hand: M q_dd - tau - tau_g + J_C^T f, 2F rows
    row_hand_idx: np.ndarray  # (F, 2) the hand rows per finger and joint
    num_body_rows: int  # object and hand rows, before the contact rows

    @property
    def num_fingers(self) -> int:
        return self.block.num_fingers


@functools.cache
def knot_layout(num_fingers: int) -> KnotLayout:
    """The KnotLayout of a hand of `num_fingers` fingers (one per finger count: a pure function)."""
    block = knot_block(num_fingers)
    fingers = np.arange(num_fingers)

    def per_joint(name: str) -> np.ndarray:
        return block.slices[name].start + 2 * fingers[:, None] + TWO

    row_hand = slice(3, 3 + 2 * num_fingers)
    return KnotLayout(
        block=block,
        col_q=per_joint("q"),
        col_qd=per_joint("qd"),
        col_qdd=per_joint("qdd"),
        col_tau=per_joint("tau"),
        col_ln=block.slices["lambda_n"].start + fingers,
        col_lt=block.slices["lambda_t"].start + fingers,
        col_g=block.slices["slack"].start + fingers,
        row_hand=row_hand,
        row_hand_idx=row_hand.start + 2 * fingers[:, None] + TWO,
        num_body_rows=row_hand.stop,
    )
