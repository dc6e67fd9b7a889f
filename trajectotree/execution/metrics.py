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

Divergence (`detect_divergence`): a run whose state stops being finite, whose object moves faster
than gravity, the push and the fingers together could make it, or in which Drake refused a step,
is no longer a simulation of anything: its outcome is "diverged", not a drop (results.RunOutcome).
Its samples from then on count for nothing: the drop rule looks at those before, and the errors
(final_error too) are held at the last sample before it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from trajectotree.results import SimLog, SimResult

# m/s, more than the fingers can give the object: fingers chattering at gains far beyond their ranges (a
# fingertip spring of 1e12 N/m) flung the 50 g box at 10 m/s at most; gravity and a push add their own
MAX_THROW_SPEED = 100.0


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


def detect_divergence(log: SimLog, gravity: float, push_speed: float) -> tuple[int, str | None]:
    """(the number of samples before the run diverged, why it diverged; None: it did not), for
    `gravity` m/s^2 and a push that can add at most `push_speed` m/s. The object starts at rest, so
    at time t it cannot be faster than MAX_THROW_SPEED + push_speed + gravity t."""
    t, x = np.asarray(log.t, dtype=float), np.asarray(log.x, dtype=float)
    state = np.concatenate([x, np.asarray(log.q, dtype=float).reshape(len(t), -1)], axis=1)
    broken = np.flatnonzero(~np.all(np.isfinite(state), axis=1))
    good = int(broken[0]) if broken.size else len(t)
    with np.errstate(invalid="ignore", divide="ignore"):
        dt = np.diff(t[:good])
        speed = np.where(dt > 0, np.linalg.norm(np.diff(x[:good, :2], axis=0), axis=1) / dt, 0.0)
    limit = MAX_THROW_SPEED + push_speed + gravity * t[1:good]
    fast = np.flatnonzero(speed > limit)
    if fast.size:
        k = int(fast[0])
        return k + 1, (
            f"the object moved at {speed[k]:.3g} m/s at {t[k + 1]:.2f} s, faster than gravity, the push and the "
            f"fingers could make it ({limit[k]:.3g} m/s)"
        )
    if good < len(t):
        return good, f"the state is not finite at {t[good]:.2f} s"
    if log.step_error is not None:
        return good, f"Drake refused a step after {t[-1]:.2f} s ({log.step_error.strip().splitlines()[0]})"
    return good, None


def hold_from(abs_error, k: int) -> np.ndarray:
    """(T, 3) abs_error with every sample from k on replaced by the one before it."""
    held = np.array(abs_error, dtype=float)
    held[max(k, 1) :] = held[max(k, 1) - 1]
    return held


def hold_after_drop(t, abs_error, drop_time: float | None) -> np.ndarray:
    """(T, 3) abs_error with every sample after drop_time replaced by the one at it."""
    held = np.array(abs_error, dtype=float)
    if drop_time is not None:
        after = np.asarray(t) > drop_time
        if after.any():
            held[after] = held[np.flatnonzero(~after)[-1]]
    return held


def evaluate(log: SimLog, drop_distance: float, gravity: float, push_speed: float = 0.0) -> SimResult:
    """The run's tracking metrics against the planned object trajectory, with the drop
    rule at `drop_distance` (m, SimConfig.drop_distance) and the divergence test for `gravity`
    (m/s^2) and a push that adds at most `push_speed` m/s (detect_divergence)."""
    good, divergence = detect_divergence(log, gravity, push_speed)
    with np.errstate(invalid="ignore"):
        error = hold_from(absolute_error(log.x, log.x_plan), good) if divergence else absolute_error(log.x, log.x_plan)
    dropped, drop_time = detect_drop(log.t[:good], log.x[:good], log.x_plan[:good], drop_distance)
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
        diverged_at_s=None if divergence is None else float(log.t[min(good, len(log.t) - 1)]),
        divergence=divergence,
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
