"""Where a plan begins: the object's measured pose and velocity, the hand's joint angles and,
optionally, where each finger touches the object (start.json, trajectotree.io).

A plan from a start state roots the contact search at that grasp and fixes CITO's first knot to
that state (trajectotree.planning.start checks it first). Units: m, rad, m/s, rad/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trajectotree.config import ConfigError

NUM_JOINTS = 8  # the hand's joints, finger-major (finger i: joints 2i, 2i + 1)


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
