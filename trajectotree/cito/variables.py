"""Decision variables of the CITO program, one row per knot.

`CitoVariables.from_prog` creates them; `eval_result` returns the same dataclass
holding numbers. Per knot k: object pose x = (p_x, p_y, theta), its velocity and
acceleration; joint angles q, velocities, accelerations and torques (2F each for
F fingers, finger-major); contact forces lambda_n, lambda_t (F each, on the box, in the
finger's contact frame); and one slack gamma >= 0 per finger (relaxes that
finger's contact-point equality or complementarity rows at k, L1-penalized).
Acceleration variables keep every nonlinear block local to one knot:
trapezoidal collocation is then linear.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

OBJECT_GROUPS = (("x", 3), ("xd", 3), ("xdd", 3))  # the object's block, first in every knot (F-free columns)
JOINT_GROUPS = ("q", "qd", "qdd", "tau")  # two per finger, finger-major
FINGER_GROUPS = ("lambda_n", "lambda_t", "slack")  # one per finger


@dataclass(frozen=True)
class KnotBlock:
    """The layout of one knot's variables for a hand of `num_fingers` two-joint fingers."""

    num_fingers: int
    groups: tuple[tuple[str, int], ...]  # (name, width) of each group, in the order of a knot's block
    slices: dict  # name -> slice of the group inside a knot block
    size: int  # KNOT_SIZE: the variables of one knot

    def width(self, *names: str) -> int:
        """The number of variables in the named groups of a knot block."""
        return sum(self.slices[name].stop - self.slices[name].start for name in names)


@functools.cache
def knot_block(num_fingers: int) -> KnotBlock:
    """The KnotBlock of a hand of `num_fingers` fingers (one per finger count: a pure function)."""
    groups = (
        *OBJECT_GROUPS,
        *((name, 2 * num_fingers) for name in JOINT_GROUPS),
        *((name, num_fingers) for name in FINGER_GROUPS),
    )
    slices, start = {}, 0
    for name, w in groups:
        slices[name] = slice(start, start + w)
        start += w
    return KnotBlock(num_fingers=num_fingers, groups=groups, slices=slices, size=start)


def fingers_of_block(size: int) -> int:
    """The finger count whose knot block has `size` variables (9 + 11 F)."""
    fixed, per_finger = knot_block(0).size, knot_block(1).size - knot_block(0).size
    if size < fixed or (size - fixed) % per_finger:
        raise ValueError(f"{size} variables are no knot block (9 + 11 per finger)")
    return (size - fixed) // per_finger


@dataclass(frozen=True)
class CitoVariables:
    x: np.ndarray  # (K, 3)
    xd: np.ndarray  # (K, 3)
    xdd: np.ndarray  # (K, 3)
    q: np.ndarray  # (K, 2F)
    qd: np.ndarray  # (K, 2F)
    qdd: np.ndarray  # (K, 2F)
    tau: np.ndarray  # (K, 2F)
    lambda_n: np.ndarray  # (K, F)
    lambda_t: np.ndarray  # (K, F)
    slack: np.ndarray  # (K, F)

    @property
    def num_knots(self) -> int:
        return self.x.shape[0]

    @property
    def num_fingers(self) -> int:
        return self.lambda_n.shape[1]

    @staticmethod
    def from_prog(prog, num_knots: int, num_fingers: int) -> CitoVariables:
        return CitoVariables(
            **{name: prog.NewContinuousVariables(num_knots, w, name) for name, w in knot_block(num_fingers).groups}
        )

    def knot(self, k: int) -> np.ndarray:
        """The KnotBlock.size variables (or values) of knot k, in its groups' order."""
        return np.concatenate([getattr(self, name)[k] for name, _ in knot_block(self.num_fingers).groups])

    def stacked(self) -> np.ndarray:
        """(K, KnotBlock.size): every knot's block."""
        return np.concatenate([getattr(self, name) for name, _ in knot_block(self.num_fingers).groups], axis=1)

    @staticmethod
    def from_stacked(blocks: np.ndarray) -> CitoVariables:
        block = knot_block(fingers_of_block(blocks.shape[1]))
        return CitoVariables(**{name: np.array(blocks[:, block.slices[name]]) for name, _ in block.groups})

    def eval_result(self, result) -> CitoVariables:
        """The same fields as numbers, from a MathematicalProgramResult."""
        return CitoVariables(**{f.name: result.GetSolution(getattr(self, f.name)) for f in fields(self)})

    def set_initial_guess(self, prog, guess: CitoVariables) -> None:
        for f in fields(self):
            prog.SetInitialGuess(getattr(self, f.name), getattr(guess, f.name))
