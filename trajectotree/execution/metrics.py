"""Tracking metrics of an executed plan (pure numpy functions): `evaluate` turns the
SimLog a simulation recorded into its SimResult (the log and the metrics below).

Errors compare the simulated object pose (x, y, theta) with the planned one at
the same times. theta is the planar joint's unwrapped angle, so a box that spins
a full turn counts as 2 pi off, not 0.

Drop rule: the box is dropped at the first sample where its position is farther
than `drop_distance` (SimConfig, default 5 cm, a quarter of the box's length)
from the planned position. A box that leaves the fingers falls under gravity
and crosses this distance within ~0.1 s; a held box stays within millimetres.
There is no floor, so a dropped box falls for ever: from the drop on, the tracking
error is held at its value at the drop (`hold_after_drop`), as if the box lay where
it left the hand; otherwise metres of free fall would swamp every mean.
`final_error` is the error at the last sample all the same (a box the fingers caught
again after the drop rule fired may end on the plan), and `error_at_drop` the held value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from trajectotree.results import SimLog, SimResult


def absolute_error(pose, pose_ref) -> np.ndarray:
    """(T, 3) |pose - pose_ref| per sample for (x m, y m, theta rad)."""
    return np.abs(np.asarray(pose, dtype=float) - np.asarray(pose_ref, dtype=float))


def mean_absolute_error(abs_error) -> np.ndarray:
    """(3,) the time mean of an absolute error series (T, 3) (uniform samples)."""
    return np.mean(np.asarray(abs_error, dtype=float), axis=0)


def final_error(abs_error) -> np.ndarray:
    """(3,) the absolute error at the last sample."""
    return np.asarray(abs_error, dtype=float)[-1].copy()


def detect_drop(t, pose, pose_ref, drop_distance: float) -> tuple[bool, float | None]:
    """(dropped, time of the first sample beyond drop_distance, or None)."""
    distance = np.linalg.norm(np.asarray(pose, dtype=float)[:, :2] - np.asarray(pose_ref, dtype=float)[:, :2], axis=1)
    beyond = np.flatnonzero(distance > drop_distance)
    if beyond.size == 0:
        return False, None
    return True, float(np.asarray(t)[beyond[0]])


def hold_after_drop(t, abs_error, drop_time: float | None) -> np.ndarray:
    """(T, 3) abs_error with every sample after drop_time replaced by the one at it."""
    held = np.array(abs_error, dtype=float)
    if drop_time is not None:
        after = np.asarray(t) > drop_time
        if after.any():
            held[after] = held[np.flatnonzero(~after)[-1]]
    return held


def evaluate(log: SimLog, drop_distance: float) -> SimResult:
    """The run's tracking metrics against the planned object trajectory, with the drop
    rule at `drop_distance` (m, SimConfig.drop_distance)."""
    dropped, drop_time = detect_drop(log.t, log.x, log.x_plan, drop_distance)
    error = absolute_error(log.x, log.x_plan)
    abs_error = hold_after_drop(log.t, error, drop_time)
    mae = mean_absolute_error(abs_error)
    return SimResult(
        **{f.name: getattr(log, f.name) for f in fields(SimLog)},
        abs_error=abs_error,
        mae_x=float(mae[0]),
        mae_y=float(mae[1]),
        mae_theta=float(mae[2]),
        final_error=tuple(float(v) for v in final_error(error)),
        dropped=dropped,
        drop_time_s=drop_time,
        error_at_drop=None if drop_time is None else tuple(float(v) for v in abs_error[-1]),
    )


@dataclass(frozen=True)
class ConfidenceInterval:
    mean: np.ndarray  # sample mean across trials
    lower: np.ndarray  # lower bound of the interval
    upper: np.ndarray  # upper bound of the interval
    count: int  # number of trials


def mean_confidence_interval(samples, confidence: float = 0.95, axis: int = 0) -> ConfidenceInterval:
    """Mean across trials (along `axis`) with a two-sided Student-t confidence
    interval: mean +- t_{(1+c)/2, n-1} s / sqrt(n). With one trial the bounds are
    the mean itself (no spread to estimate); NaN samples are rejected."""
    data = np.asarray(samples, dtype=float)
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence = {confidence!r} is out of range; valid range: (0, 1)")
    if data.size == 0 or data.shape[axis] == 0:
        raise ValueError("mean_confidence_interval needs at least one trial")
    if np.any(np.isnan(data)):
        raise ValueError("mean_confidence_interval got NaN samples")
    n = data.shape[axis]
    mean = np.mean(data, axis=axis)
    if n == 1:
        return ConfidenceInterval(mean=mean, lower=mean.copy(), upper=mean.copy(), count=1)
    from scipy import stats  # here: importing scipy.stats takes 1.7 s, and only the figures need it

    half = stats.t.ppf((1.0 + confidence) / 2.0, n - 1) * np.std(data, axis=axis, ddof=1) / math.sqrt(n)
    return ConfidenceInterval(mean=mean, lower=mean - half, upper=mean + half, count=n)
