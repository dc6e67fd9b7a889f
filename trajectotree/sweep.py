"""The paper's experiment: random goal rotations and trials over them."""

from __future__ import annotations

import math

import numpy as np


def sample_goals(count: int, seed: int) -> np.ndarray:
    """`count` goal rotations (rad) drawn uniformly from [-pi, pi] with `seed`.
    The same seed always gives the same goals (paper Sec. IV-A: 60 goals)."""
    return np.random.default_rng(seed).uniform(-math.pi, math.pi, count)
