"""The scene's configuration: the hand, the object and the world (SceneConfig, ObjectConfig)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trajectotree.config.checks import (
    ConfigError,
    check_length,
    check_range,
    interval,
    is_file,
)
from trajectotree.geometry import ConvexPolygon, ellipse_points, polygon_problem

DEFAULT_HAND = "planar_hand"
# built-in hands, models/NAME.yaml (trajectotree.scene.hand); any other is a PATH.yaml, PATH.sdf or PATH.urdf
HAND_NAMES = ("planar_hand", "drake_planar_gripper", "planar_hand5")
# The built-in hands in space (models/NAME.yaml with kind: space, trajectotree.scene.spatial); only
# `trajectotree scene` and `trajectotree search` take them so far, every planar stage refuses them (issue 36).
SPACE_HAND_NAMES = ("fingerpro4",)
HAND_SUFFIXES = (".yaml", ".yml", ".sdf", ".urdf")
# (low, high) of the object's pose x m, y m, theta rad in W where a plan may start (scene.initial_pose, a start state)
INITIAL_POSE_BOUNDS = ((-1.0, 1.0), (-1.0, 1.0), (-100.0, 100.0))  # theta: many turns
MAX_OBJECT_SIZE = 0.3  # m, the object's largest extent along any axis, and its outline's largest radius
MAX_MU = 5.0  # the friction coefficient at most: rubber on rubber is about 1-2
# kg, the object's mass: at most far beyond what the 1 N m motors hold (the payload check names the hand's limit); at
# least a gram, for Drake's discrete contact solver fails on a lighter object (1e-300 kg: a NaN Hessian at once)
MIN_BOX_MASS, MAX_BOX_MASS = 0.001, 10.0
MAX_GRAVITY = 100.0  # m/s^2, ten times Earth's: beyond it no hand model here holds any object


def check_hand(value) -> None:
    """Raises ConfigError unless `value` names a built-in hand or an existing hand file (its
    contents are checked when the scene reads it: trajectotree.scene.hand)."""
    valid = f"{', '.join(HAND_NAMES + SPACE_HAND_NAMES)}, or an existing PATH.yaml, PATH.sdf or PATH.urdf"
    problem = None
    if not isinstance(value, str) or not value:
        problem = "is not a hand name or file"
    elif value in HAND_NAMES + SPACE_HAND_NAMES:
        return
    elif Path(value).suffix.lower() not in HAND_SUFFIXES:
        problem = "is not a hand name or file"
    elif not is_file(value):
        problem = "does not exist"
    if problem:
        raise ConfigError(field="scene.hand", value=value, problem=problem, valid=valid, label="valid")


@dataclass(frozen=True)
class ObjectConfig:
    """The object's outline when it is not the box (SceneConfig.shape): one of a polygon's
    vertices, a disc's radius or an ellipse's semi-axes (the round ones are polygonized,
    geometry.ellipse_points)."""

    # m, (x, y) vertices of a convex polygon in the object frame, in either orientation; it is made
    # counter-clockwise and re-centred at its area centroid. None: the box_width x box_height box.
    vertices: tuple[tuple[float, float], ...] | None = None
    circle_radius: float | None = None  # m, a disc of this radius
    ellipse_semi_axes: tuple[float, float] | None = None  # m, an ellipse's semi-axes along the object's x and y

    def __post_init__(self):
        given = [n for n in ("vertices", "circle_radius", "ellipse_semi_axes") if getattr(self, n) is not None]
        if len(given) > 1:
            raise ConfigError(f"scene.object: {' and '.join(given)} both describe the object; give one of them")
        if self.circle_radius is not None:
            check_range("scene.object.circle_radius", self.circle_radius, 0.0, MAX_OBJECT_SIZE, low_open=True)
        if self.ellipse_semi_axes is not None:
            check_length("scene.object.ellipse_semi_axes", self.ellipse_semi_axes, 2, "a, b in m")
            for i, a in enumerate(self.ellipse_semi_axes):
                check_range("scene.object.ellipse_semi_axes", a, 0.0, MAX_OBJECT_SIZE, low_open=True, index=(i,))
        if self.vertices is None:
            return
        for i, v in enumerate(self.vertices):
            if len(v) != 2:
                raise ConfigError(
                    field="scene.object.vertices",
                    index=(i,),
                    value=list(v),
                    problem="is not a pair",
                    valid="(x, y) in m",
                )
            for j, c in enumerate(v):
                check_range("scene.object.vertices", c, -1.0, 1.0, index=(i, j))  # m, before re-centring
        problem = polygon_problem(self.vertices)
        if problem:
            listed = [list(v) for v in self.vertices]
            shown = None if len(listed) <= 8 else f"[{len(listed)} vertices: {listed[0]}, ..., {listed[-1]}]"
            raise ConfigError(
                field="scene.object.vertices",
                value=listed,
                shown=shown,  # one line a person reads, however many vertices
                problem=f": {problem}",
                valid="at least 3 distinct (x, y) vertices in convex position",
            )

    @property
    def field_name(self) -> str:
        """The field that describes the object, for messages ("scene.object.vertices")."""
        given = [n for n in ("vertices", "circle_radius", "ellipse_semi_axes") if getattr(self, n) is not None]
        return "scene.object." + (given[0] if given else "vertices")

    @property
    def is_box(self) -> bool:
        """No outline given: the object is SceneConfig's box_width x box_height box."""
        return self.vertices is None and self.circle_radius is None and self.ellipse_semi_axes is None

    def outline(self) -> np.ndarray | None:
        """(V, 2) m, the polygon's vertices, the round shape's polygonized outline, or None (the box)."""
        if self.circle_radius is not None:
            return ellipse_points(self.circle_radius, self.circle_radius)
        if self.ellipse_semi_axes is not None:
            return ellipse_points(*self.ellipse_semi_axes)
        return None if self.vertices is None else np.asarray(self.vertices, dtype=float)


@dataclass(frozen=True)
class SceneConfig:
    """The hand, the object and the world."""

    box_width: float = 0.20  # m, object extent along its x axis
    box_height: float = 0.10  # m, object extent along its y axis
    box_depth: float = 0.05  # m, extent along z (only for 3D geometry; the task is planar)
    box_mass: float = 0.05  # kg, the object's mass (box or polygon)
    # kg m^2, the object's moment of inertia about z at its centroid; None: a uniform plate's (shape.inertia)
    object_inertia: float | None = None
    mu: float = 0.7  # friction coefficient between fingertips and object
    gravity: float = 9.81  # m/s^2, magnitude; gravity points along -y in W
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (m, m, rad) object pose x_0 in W
    corner_margin: float = 0.015  # m, contacts closer than this (arclength) to a corner are not allowed
    object: ObjectConfig = field(default_factory=ObjectConfig)  # a convex polygon instead of the box
    # the hand: a built-in name (HAND_NAMES) or a file, PATH.yaml or PATH.sdf / PATH.urdf with PATH.yaml beside it
    hand: str = DEFAULT_HAND

    @functools.cached_property
    def shape(self) -> ConvexPolygon:
        """The object's outline in its frame B: the polygon, disc or ellipse of `object`, else the box."""
        if self.object.is_box:
            return ConvexPolygon.box(self.box_width, self.box_height)
        return ConvexPolygon.from_points(self.object.outline(), smooth=self.object.vertices is None)

    def inertia_zz(self, mass: float | None = None) -> float:
        """kg m^2, the object's moment of inertia about z at its centroid for `mass` kg (None:
        box_mass): object_inertia scaled by mass / box_mass, else a uniform plate's."""
        mass = self.box_mass if mass is None else mass
        if self.object_inertia is None:
            return self.shape.inertia(mass)
        return self.object_inertia if mass == self.box_mass else self.object_inertia * mass / self.box_mass

    def _check_inertia_is_physical(self) -> None:
        """ConfigError unless object_inertia and the prism's other moments (uniform, box_depth deep)
        satisfy the triangle inequality, without which Drake's parser replaces the whole inertia."""
        if self.object.is_box:
            Sxx, Syy, Sxy = self.box_width**2 / 12, self.box_height**2 / 12, 0.0
        else:
            Sxx, Syy, Sxy = self.shape.second_moments()
        low = self.box_mass * math.hypot(Sxx - Syy, 2 * Sxy)  # the in-plane principal moments' difference
        high = self.box_mass * (Sxx + Syy + self.box_depth**2 / 6)
        if not low <= self.object_inertia <= high:
            raise ConfigError(
                field="scene.object_inertia",
                value=self.object_inertia,
                problem=f"cannot be the object's: with its other moments (a uniform {self.box_depth:g} m deep prism of "
                f"{self.box_mass:g} kg) it breaks the triangle inequality",
                valid=f"[{low:.3g}, {high:.3g}] kg m^2",
            )

    def __post_init__(self):
        for name in ("box_width", "box_height", "box_depth"):
            check_range(f"scene.{name}", getattr(self, name), 0.0, MAX_OBJECT_SIZE, low_open=True)
        check_range("scene.box_mass", self.box_mass, MIN_BOX_MASS, MAX_BOX_MASS)
        check_range("scene.gravity", self.gravity, 0.0, MAX_GRAVITY, low_open=True)
        if self.object_inertia is not None:
            check_range("scene.object_inertia", self.object_inertia, 0.0, 1.0, low_open=True)
            self._check_inertia_is_physical()
        check_range("scene.mu", self.mu, 0.0, MAX_MU, low_open=True)
        check_length("scene.initial_pose", self.initial_pose, 3, "x m, y m, theta rad")
        for i, (v, (low, high)) in enumerate(zip(self.initial_pose, INITIAL_POSE_BOUNDS)):
            check_range("scene.initial_pose", v, low, high, index=(i,))
        # m, half the largest side: a larger margin leaves no face a contact
        check_range("scene.corner_margin", self.corner_margin, 0.0, MAX_OBJECT_SIZE / 2)
        check_hand(self.hand)
        if self.object.is_box:
            shortest = 2 * self.corner_margin  # each face must keep some contact points between its corner margins
            if min(self.box_width, self.box_height) <= shortest:
                raise ConfigError(
                    field="scene.box_width x scene.box_height",
                    value=(self.box_width, self.box_height),
                    shown=f"{self.box_width:g} x {self.box_height:g} m",
                    problem=f"is too small: contacts keep scene.corner_margin = {self.corner_margin:g} m from each "
                    f"corner, so each side must be longer than {shortest:g} m",
                    valid=f"{interval(shortest, MAX_OBJECT_SIZE, low_open=True)} m",
                    label="valid range of each side",
                )
            return
        shape = self.shape
        margins = shape.corner_margins(self.corner_margin)
        room = shape.edge_lengths - margins - np.roll(margins, -1)  # face f runs from vertex f to f + 1
        if room.min() <= 0:
            f = int(room.argmin())
            ends = margins[f], margins[(f + 1) % len(margins)]
            raise ConfigError(
                field=self.object.field_name,
                problem=f"edge {f} is {shape.edge_lengths[f]:.4g} m long; contacts keep {ends[0]:.3g} m and "
                f"{ends[1]:.3g} m from its corners (scene.corner_margin = {self.corner_margin:g} m at a right angle, "
                f"less at a blunter corner), so it must be longer than {sum(ends):.3g} m",
            )
        # m: a disc of radius 0.3 m has its polygonized vertices (radius x cos, sin) and their re-centring at the
        # area centroid each ~1e-16 m off, which must not make it larger than its radius
        rounding = 1e-12
        if shape.circumradius > MAX_OBJECT_SIZE + rounding:
            raise ConfigError(
                field=self.object.field_name,
                problem=f"a vertex is {shape.circumradius:.3g} m from the centroid",
                valid=f"at most {MAX_OBJECT_SIZE:g} m",
            )
