"""Where a plan begins: the object's measured pose and velocity, the hand's joint angles and,
optionally, where each finger touches the object (start.json, trajectotree.io).

A plan from a start state roots the contact search at that grasp and fixes CITO's first knot to
that state (trajectotree.planning.start checks it first). Units: m, rad, m/s, rad/s.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from trajectotree.config import ConfigError

NUM_JOINTS = 8  # the hand's joints, finger-major (finger i: joints 2i, 2i + 1)


class StartProblem(enum.Enum):
    MOVING = "the object is moving"
    SPINNING = "the object is turning"
    FINGER_OFF = "a fingertip does not touch the object"
    CONTACT_MISMATCH = "a given contact is not where the fingertip is"
    NOT_IN_CLOSURE = "the grasp cannot hold the object"


@dataclass(frozen=True)
class StartRefusal:
    """Why a start state cannot be planned from, with its numbers."""

    problem: StartProblem
    finger: int | None = None
    value: float = float("nan")  # the measured quantity (m, m/s or the friction the grasp needs)
    limit: float = float("nan")  # what it may be at most

    def to_json(self) -> dict:
        numbers = {k: float(v) for k, v in (("value", self.value), ("limit", self.limit)) if math.isfinite(v)}
        return {"kind": "start", "problem": self.problem.name.lower(), **numbers} | (
            {} if self.finger is None else {"finger": int(self.finger)}
        )

    def __str__(self) -> str:
        if self.problem is StartProblem.MOVING:
            return (
                f"start: the object moves at {self.value:.3g} m/s; a plan starts at rest (at most {self.limit:g} m/s)"
            )
        if self.problem is StartProblem.SPINNING:
            return f"start: the object turns at {self.value:.3g} rad/s; a plan starts at rest (at most {self.limit:g})"
        if self.problem is StartProblem.FINGER_OFF:
            return (
                f"start: fingertip {self.finger} is {self.value * 1e3:.2f} mm from the object's surface; every "
                f"finger must touch it (within {self.limit * 1e3:g} mm) to start a plan"
            )
        if self.problem is StartProblem.CONTACT_MISMATCH:
            return (
                f"start: finger {self.finger}'s given contact is {self.value * 1e3:.2f} mm from its fingertip's "
                f"contact point; at most {self.limit * 1e3:g} mm"
            )
        return (
            f"start: the grasp of fingers (0, 1, 2, 3) is not in frictional form closure at mu_plan "
            f"{self.limit:.3g}; it needs mu {self.value:.3g}"
        )


@dataclass(frozen=True)
class StartState:
    """A measured state to plan from; the object must be (nearly) at rest in a grasp of every finger."""

    object_pose: tuple[float, float, float]  # (x m, y m, theta rad) in W
    q: tuple[float, ...]  # (8,) rad, joint angles, finger-major
    object_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (m/s, m/s, rad/s) in W
    # m, each finger's contact as an arclength along the object's boundary (geometry.ConvexPolygon);
    # None: derived from the fingertip positions (those touching the surface)
    arclengths: tuple[float, ...] | None = None

    def __post_init__(self):
        _check_vector("start.object_pose", self.object_pose, 3)
        _check_vector("start.q", self.q, NUM_JOINTS)
        _check_vector("start.object_velocity", self.object_velocity, 3)
        if self.arclengths is not None:
            _check_vector("start.arclengths", self.arclengths, NUM_JOINTS // 2)

    def to_json(self) -> dict:
        return {
            "object_pose": [float(v) for v in self.object_pose],
            "object_velocity": [float(v) for v in self.object_velocity],
            "q": [float(v) for v in self.q],
            "arclengths": None if self.arclengths is None else [float(s) for s in self.arclengths],
        }

    @staticmethod
    def from_json(data, where: str = "start") -> StartState:
        if not isinstance(data, dict):
            raise ConfigError(
                f"{where}: a start state is a JSON object with object_pose, q (and optionally "
                f"object_velocity, arclengths); got {type(data).__name__}"
            )
        unknown = set(data) - {"object_pose", "object_velocity", "q", "arclengths"}
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {sorted(unknown)}; valid: object_pose, object_velocity, q, arclengths"
            )
        for key in ("object_pose", "q"):
            if key not in data:
                raise ConfigError(f"{where}: missing {key!r}")
        try:
            return StartState(
                object_pose=tuple(float(v) for v in data["object_pose"]),
                q=tuple(float(v) for v in data["q"]),
                object_velocity=tuple(float(v) for v in data.get("object_velocity") or (0.0, 0.0, 0.0)),
                arclengths=None if data.get("arclengths") is None else tuple(float(s) for s in data["arclengths"]),
            )
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{where}: every entry must be a number ({e})") from None

    @staticmethod
    def from_run(t: np.ndarray, x: np.ndarray, q: np.ndarray, time_s: float) -> StartState:
        """The state of a recorded run (sim.npz's t, x, q) at its sample nearest `time_s`, the object's
        velocity by central differences."""
        k = int(np.argmin(np.abs(np.asarray(t) - time_s)))
        lo, hi = max(k - 1, 0), min(k + 1, len(t) - 1)
        velocity = (x[hi] - x[lo]) / (t[hi] - t[lo]) if hi > lo else np.zeros(3)
        return StartState(object_pose=tuple(x[k]), q=tuple(q[k]), object_velocity=tuple(velocity))


def _check_vector(name: str, values, size: int) -> None:
    if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") or len(values) != size:
        raise ConfigError(f"{name} = {values!r} must have {size} numbers")
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise ConfigError(f"{name}[{i}] = {v!r} is not a finite number")
