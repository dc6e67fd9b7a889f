"""Decision variables of the CITO program, one row per knot.

`CitoVariables.from_prog` creates them; `eval_result` returns the same dataclass
holding numbers. Per knot k: object pose x = (p_x, p_y, theta), its velocity and
acceleration; joint angles q, velocities, accelerations and torques (8 each,
finger-major); contact forces lambda_n, lambda_t (4 each, on the box, in the
finger's contact frame); and one slack gamma >= 0 per finger (relaxes that
finger's contact-point equality or complementarity rows at k, L1-penalized).
Acceleration variables keep every nonlinear block local to one knot:
trapezoidal collocation is then linear.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from trajectotree.scene.plant import NUM_FINGERS, NUM_HAND_JOINTS

# (name, width) of each group, in the order of a knot's variable block.
GROUPS = (
    ("x", 3),
    ("xd", 3),
    ("xdd", 3),
    ("q", NUM_HAND_JOINTS),
    ("qd", NUM_HAND_JOINTS),
    ("qdd", NUM_HAND_JOINTS),
    ("tau", NUM_HAND_JOINTS),
    ("lambda_n", NUM_FINGERS),
    ("lambda_t", NUM_FINGERS),
    ("slack", NUM_FINGERS),
)
KNOT_SIZE = sum(w for _, w in GROUPS)
# Slice of each group inside a knot block.
SLICES = {}
_start = 0
for _name, _width in GROUPS:
    SLICES[_name] = slice(_start, _start + _width)
    _start += _width


def width(*names: str) -> int:
    """The number of variables in the named groups of a knot block."""
    return sum(SLICES[name].stop - SLICES[name].start for name in names)


@dataclass(frozen=True)
class CitoVariables:
    x: np.ndarray  # (K, 3)
    xd: np.ndarray  # (K, 3)
    xdd: np.ndarray  # (K, 3)
    q: np.ndarray  # (K, 8)
    qd: np.ndarray  # (K, 8)
    qdd: np.ndarray  # (K, 8)
    tau: np.ndarray  # (K, 8)
    lambda_n: np.ndarray  # (K, 4)
    lambda_t: np.ndarray  # (K, 4)
    slack: np.ndarray  # (K, 4)

    @property
    def num_knots(self) -> int:
        return self.x.shape[0]

    @staticmethod
    def from_prog(prog, num_knots: int) -> CitoVariables:
        return CitoVariables(**{name: prog.NewContinuousVariables(num_knots, width, name) for name, width in GROUPS})

    def knot(self, k: int) -> np.ndarray:
        """The KNOT_SIZE variables (or values) of knot k, in GROUPS order."""
        return np.concatenate([getattr(self, name)[k] for name, _ in GROUPS])

    def stacked(self) -> np.ndarray:
        """(K, KNOT_SIZE): every knot's block."""
        return np.concatenate([getattr(self, name) for name, _ in GROUPS], axis=1)

    @staticmethod
    def from_stacked(blocks: np.ndarray) -> CitoVariables:
        return CitoVariables(**{name: np.array(blocks[:, SLICES[name]]) for name, _ in GROUPS})

    def eval_result(self, result) -> CitoVariables:
        """The same fields as numbers, from a MathematicalProgramResult."""
        return CitoVariables(**{f.name: result.GetSolution(getattr(self, f.name)) for f in fields(self)})

    def set_initial_guess(self, prog, guess: CitoVariables) -> None:
        for f in fields(self):
            prog.SetInitialGuess(getattr(self, f.name), getattr(guess, f.name))
