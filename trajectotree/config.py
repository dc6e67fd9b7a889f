"""Typed configuration: every parameter a user may change, with its unit.

Defaults equal the paper's setup (Chen et al., TrajectoTree, Sec. IV-A). Each dataclass validates itself on
construction and raises `ConfigError` naming the field, its value and the valid range. `load_config` /
`save_config` read and write the whole `Config` as YAML with Drake's typed YAML functions (yaml_load_typed,
yaml_dump_typed, through trajectotree.typed_yaml), which check each value's type; `config_from_dict` reads the
same sections from plan.json and sweep manifests.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml  # only for yaml.YAMLError, the parse error Drake's YAML functions raise

from trajectotree.geometry import ConvexPolygon, ellipse_points, polygon_problem
from trajectotree.typed_yaml import DRAKE_ERRORS, drake_yaml, freeze, load_typed, thaw

_NO_VALUE = object()  # a ConfigError about a field whose value its message does not repeat
MAX_GOAL_ROTATION = 20 * math.pi  # rad, the largest goal rotation either way: ten turns
DEFAULT_HAND = "planar_hand"
# built-in hands, models/NAME.yaml (trajectotree.scene.hand); any other is a PATH.yaml, PATH.sdf or PATH.urdf
HAND_NAMES = ("planar_hand", "drake_planar_gripper", "planar_hand5")
HAND_SUFFIXES = (".yaml", ".yml", ".sdf", ".urdf")
MAX_NODES = 400  # search.num_nodes at most: a ten-turn goal takes 238 with the default segment rotations


class ConfigError(ValueError):
    """An invalid configuration or command-line value (CLI exit code 2).

    An error about one value carries its `field` (a config field such as "scene.box_mass", or an
    option such as "--goal"), the element `index` within it, the `value` given (`shown` writes it
    otherwise than repr), what is wrong with it (`problem`: "is out of range", or after a colon a
    sentence of its own) and the `valid` range or `choices` (`label` names them otherwise than
    "valid range" / "valid"). Its message is built from them, so the CLI can name the option that
    set the field (`as_option`). An error about anything else (a file, two options together) is
    its message alone, with field None."""

    def __init__(
        self,
        message: str | None = None,
        *,
        field: str | None = None,
        value=_NO_VALUE,
        problem: str = "is out of range",
        valid: str | None = None,
        choices: tuple[str, ...] | None = None,
        index: tuple[int, ...] = (),
        shown: str | None = None,
        label: str | None = None,
        option: str | None = None,
    ):
        if (message is None) == (field is None):
            raise TypeError("ConfigError takes a message or a field, not both")
        self.field, self.value, self.problem, self.index = field, value, problem, index
        self.valid = ", ".join(choices) if choices is not None else valid
        self.choices, self.shown, self.label, self.option = choices, shown, label, option
        super().__init__(message if field is None else self._text())

    @property
    def subject(self) -> str:
        """How the message names the value: the field with its index, after the option that set it."""
        named = self.field + "".join(f"[{i}]" for i in self.index)
        return named if self.option is None else f"{self.option} ({named})"

    def _text(self) -> str:
        if self.value is _NO_VALUE:
            text = f"{self.subject}: {self.problem}"
        else:
            joint = "" if self.problem.startswith(":") else " "  # "is out of range", or ": a sentence of its own"
            text = f"{self.subject} = {self.shown or repr(self.value)}{joint}{self.problem}"
        if self.valid is not None:
            label = self.label or ("valid" if self.choices is not None else "valid range")
            text += f"; {label}: {self.valid}"
        return text

    def as_option(self, option: str) -> ConfigError:
        """The same error, naming the command-line `option` that set its field."""
        return ConfigError(
            field=self.field,
            value=self.value,
            problem=self.problem,
            valid=self.valid,
            choices=self.choices,
            index=self.index,
            shown=self.shown,
            label=self.label,
            option=option,
        )


def interval(low: float | None, high: float | None, *, low_open: bool = False, high_open: bool = False) -> str:
    """[low, high] as a message writes it, open at an infinite or an excluded end."""
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"


def check_range(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    index: tuple[int, ...] = (),
) -> None:
    """Raises ConfigError naming `name` (element `index`) unless `value` is a finite number
    within [low, high]."""
    valid = interval(low, high, low_open=low_open, high_open=high_open)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(field=name, index=index, value=value, problem="is not a finite number", valid=valid)
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and (value >= high if high_open else value > high)
    if too_low or too_high:
        raise ConfigError(field=name, index=index, value=value, valid=valid)


def check_integer(name: str, value, low: int, high: int | None = None) -> None:
    """Raises ConfigError naming `name` unless `value` is an integer within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(
            field=name, value=value, problem="is not an integer", valid=f"integers in {interval(low, high)}"
        )
    check_range(name, value, low, high)


def check_bool(name: str, value) -> None:
    """Raises ConfigError naming `name` unless `value` is true or false."""
    if not isinstance(value, bool):
        raise ConfigError(field=name, value=value, problem="is not true or false", choices=("true", "false"))


def check_length(name: str, value, length: int, entries: str) -> None:
    """Raises ConfigError naming `name` unless `value` has `length` entries (`entries` says which)."""
    if len(value) != length:
        raise ConfigError(field=name, value=value, problem=f"has {len(value)} entries", valid=f"{length}: {entries}")


def check_hand(value) -> None:
    """Raises ConfigError unless `value` names a built-in hand or an existing hand file (its
    contents are checked when the scene reads it: trajectotree.scene.hand)."""
    valid = f"{', '.join(HAND_NAMES)}, or an existing PATH.yaml, PATH.sdf or PATH.urdf"
    problem = None
    if not isinstance(value, str) or not value:
        problem = "is not a hand name or file"
    elif value in HAND_NAMES:
        return
    elif Path(value).suffix.lower() not in HAND_SUFFIXES:
        problem = "is not a hand name or file"
    elif not Path(value).is_file():
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
            check_range("scene.object.circle_radius", self.circle_radius, 0.0, 0.3, low_open=True)
        if self.ellipse_semi_axes is not None:
            check_length("scene.object.ellipse_semi_axes", self.ellipse_semi_axes, 2, "a, b in m")
            for i, a in enumerate(self.ellipse_semi_axes):
                check_range("scene.object.ellipse_semi_axes", a, 0.0, 0.3, low_open=True, index=(i,))
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
            raise ConfigError(
                field="scene.object.vertices",
                value=[list(v) for v in self.vertices],
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
        check_range("scene.box_width", self.box_width, 0.0, 0.30, low_open=True)
        check_range("scene.box_height", self.box_height, 0.0, 0.30, low_open=True)
        for name in ("box_depth", "box_mass", "gravity"):
            check_range(f"scene.{name}", getattr(self, name), 0.0, None, low_open=True)
        if self.object_inertia is not None:
            check_range("scene.object_inertia", self.object_inertia, 0.0, 1.0, low_open=True)
            self._check_inertia_is_physical()
        check_range("scene.mu", self.mu, 0.0, 5.0, low_open=True)
        check_length("scene.initial_pose", self.initial_pose, 3, "x m, y m, theta rad")
        for i, v in enumerate(self.initial_pose[:2]):
            check_range("scene.initial_pose", v, -1.0, 1.0, index=(i,))
        check_range("scene.initial_pose", self.initial_pose[2], -100.0, 100.0, index=(2,))  # rad: many turns
        check_range("scene.corner_margin", self.corner_margin, 0.0, None)
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
                    valid=f"{interval(shortest, 0.3, low_open=True)} m",
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
        if shape.circumradius > 0.3:
            raise ConfigError(
                field=self.object.field_name,
                problem=f"a vertex is {shape.circumradius:.3g} m from the centroid",
                valid="at most 0.3 m",
            )


@dataclass(frozen=True)
class SearchConfig:
    """The contact-sequence planner (paper Sec. III-A, Algorithm 1)."""

    # N, nodes in the object path (tree depth), incl. the start; None: from the goal's distance
    # (segments_for: the paper's 9 segments for a goal within pi, more for a longer one)
    num_nodes: int | None = None
    min_segments: int = 9  # segments of any goal the first_rotation covers: the paper's N = 10 nodes
    # rad, the rotation the first min_segments segments make together at most: the paper's half turn
    # (pi/9 each), for which the initial grasp is chosen.
    first_rotation: float = math.pi
    # rad, the most each further segment turns the object: gaiting sustained over turns needs more
    # switches than the first half turn, whose initial grasp suits it (2 pi in 18 segments: no plan from
    # the 200 best initial grasps; in 21, a plan from the first).
    max_segment_rotation: float = math.pi / 12
    # m, the most each segment moves the object: a fingertip holding its contact moves with it, and
    # 0.01 m is a third of what a pi/12 turn moves a corner of the 0.2 m box.
    max_segment_translation: float = 0.01
    num_displacements: int = 17  # |D_cp|, contact displacements per free finger (odd, incl. zero)
    # m, arclength spacing of the displacements in D_cp (17 x 0.02: moves up to 0.16 m), long enough
    # that a +-pi goal fits in the 9 contact switches of the default 10 nodes.
    displacement_step: float = 0.02
    # Initial contact of each finger: arclength (m) along the box boundary, counter-clockwise
    # from the corner (+w/2, -h/2). None: the planner ranks candidate grasps for the box and
    # roots the search at the best ones in turn (trajectotree.search.initial_grasp).
    initial_arclengths: tuple[float, ...] | None = None
    # bool: initial_arclengths are where a measured start's fingers are (trajectotree.planning.start): the
    # root keeps them even near a corner or with two fingertips closer than their diameter, as they are
    measured_start: bool = False
    nominal_joint2: float = math.pi / 4  # rad, heuristic: prefer second joints near this angle
    min_closure_margin: float = 1e-3  # N, form-closure LP margin d* must exceed this
    # Plans use mu_plan = friction_safety * scene.mu (every grasp, every three-finger stance and
    # the CITO friction cones), so the executed grasp has friction to spare. 1.0 is the paper.
    friction_safety: float = 0.7
    # bool: every three-finger stance (all four fingers in a segment without a switch) must also be in
    # closure at mu_plan, on its faces and rolled_corner_gap short of their corners, at the contacts its
    # sticking fingertip spheres roll to (trajectotree.search.stance). False: the paper.
    rolled_stances: bool = True
    # m, how far short of a corner (a vertex ending a side) a stance's rolled contacts must stay: a sphere
    # that rolls onto a corner pivots over it, its normal turning by the corner's angle; about twice the
    # rolling prediction's error in simulation (trajectotree.search.stance). Used with rolled_stances only.
    rolled_corner_gap: float = 0.002
    # m, the least gap between any two fingers' collision shapes (link boxes, fingertip spheres) at a node
    # and on the straight joint-space path from its parent (exact planar test, trajectotree.search.reach),
    # since the simulation's fingers collide like any other bodies; the initial grasps keep it too.
    finger_clearance: float = 0.002
    # N, a switch is refused when its three holding fingers need more than this total normal force
    # (at mu_plan, at their planned contacts) to carry the object's weight at either end of the
    # transition (trajectotree.search.stance): such squeezes saturate the 1 N m joints. 0: no cap (the paper).
    max_stance_force: float = 10.0
    # N, the push a stance (the fingers holding while one switches) should resist: a node's children whose
    # holding fingers resist a push of this much along each of +-x and +-y in W (trajectotree.search.stance.
    # PushCapacityLp at mu_plan, each finger within push_normal_force and its motors) are tried first, the others
    # by how far short they fall, and only then by the paper's heuristic. An order, not a test: the same tree,
    # within the same budgets. 0: the paper's order.
    push_capacity: float = 6.0
    push_normal_force: float = 8.0  # N, each finger's normal-force bound in the push capacity (the grasp controller's)
    # m, arclength spacing of the candidate initial contacts when initial_arclengths is None
    # (trajectotree.search.initial_grasp ranks every reachable grid grasp by its worst three-finger stance).
    initial_grid_step: float = 0.02
    # candidate initial grasps the search is rooted at, best first (per contact grid), many because a
    # small polygon's trees die within a few expansions, so more roots are cheap.
    max_initial_grasps: int = 200
    root_expansions: int = 2000  # node budget of the search from one initial grasp (of each window of it)
    # Segments one depth-first search looks ahead: the paper's 9, so a path of up to 9 segments is
    # searched as Algorithm 1 does; a longer one window by window (trajectotree.search.tree), which
    # keeps its search time linear in its length.
    window_segments: int = 9
    # Segments of a window's path kept before the next window is searched from their end, each kept
    # node chosen seeing the 4 beyond it (3, 4 and 6 took 10-35 % more expansions on 8 long goals).
    commit_segments: int = 5
    max_expansions: int = 20000  # node budget of the search (all initial grasps together)
    time_budget_s: float = 30.0  # s, wall-clock budget of the search
    # When the first initial grasp yields no plan, the search goes on with up to this many finer contact
    # grids too (initial_grid_step and displacement_step halved, num_displacements 2 n - 1: the same longest
    # move), the grids taking turns, one initial grasp each, within the same budgets, for objects whose
    # short faces hold few grid contacts and fingertips kept apart on one face (trajectotree.search.tree).
    # 0: the paper's single grid.
    grid_refinements: int = 1

    def __post_init__(self):
        if self.num_nodes is not None:
            check_integer("search.num_nodes", self.num_nodes, 2, MAX_NODES)
        check_integer("search.min_segments", self.min_segments, 1, MAX_NODES - 1)
        check_range("search.first_rotation", self.first_rotation, 0.0, MAX_GOAL_ROTATION)
        check_range("search.max_segment_rotation", self.max_segment_rotation, 0.01, math.pi / 2)
        check_range("search.max_segment_translation", self.max_segment_translation, 0.001, 0.1)
        check_integer("search.num_displacements", self.num_displacements, 1, 201)
        if self.num_displacements % 2 == 0:
            raise ConfigError(
                field="search.num_displacements",
                value=self.num_displacements,
                problem="is even (the displacements are symmetric around zero)",
                valid="odd integers in [1, 201]",
            )
        check_range("search.displacement_step", self.displacement_step, 0.0, 0.2, low_open=True)
        if self.initial_arclengths is not None:
            # the count must be the hand's finger count, which only the scene knows (search.tree checks it)
            if len(self.initial_arclengths) < 3:
                raise ConfigError(
                    field="search.initial_arclengths",
                    value=self.initial_arclengths,
                    problem=f"has {len(self.initial_arclengths)} entries",
                    valid="one arclength (m) per finger of the hand (at least 3)",
                )
            for i, s in enumerate(self.initial_arclengths):
                check_range("search.initial_arclengths", s, 0.0, 10.0, index=(i,))
        check_range("search.nominal_joint2", self.nominal_joint2, -math.pi, math.pi)
        check_range("search.min_closure_margin", self.min_closure_margin, 0.0, None)
        check_range("search.friction_safety", self.friction_safety, 0.0, 1.0, low_open=True)
        check_bool("search.rolled_stances", self.rolled_stances)
        check_range("search.rolled_corner_gap", self.rolled_corner_gap, 0.0, 0.05)
        check_range("search.finger_clearance", self.finger_clearance, 0.0, 0.05)
        check_range("search.max_stance_force", self.max_stance_force, 0.0, 1000.0)
        check_range("search.push_capacity", self.push_capacity, 0.0, 100.0)
        check_range("search.push_normal_force", self.push_normal_force, 0.0, 1000.0, low_open=True)
        check_range("search.initial_grid_step", self.initial_grid_step, 0.001, 0.1)
        check_integer("search.window_segments", self.window_segments, 1, 100)
        check_integer("search.commit_segments", self.commit_segments, 1, self.window_segments)
        for name in ("max_initial_grasps", "root_expansions", "max_expansions"):
            check_integer(f"search.{name}", getattr(self, name), 1)
        check_range("search.time_budget_s", self.time_budget_s, 0.0, None, low_open=True)
        check_integer("search.grid_refinements", self.grid_refinements, 0, 3)
        finest = 2**self.grid_refinements
        if (self.num_displacements - 1) * finest + 1 > 201 or self.initial_grid_step / finest < 0.001:
            raise ConfigError(
                field="search.grid_refinements",
                value=self.grid_refinements,
                problem=f"refines num_displacements {self.num_displacements} to "
                f"{(self.num_displacements - 1) * finest + 1} (at most 201) and initial_grid_step "
                f"{self.initial_grid_step} m to {self.initial_grid_step / finest:g} m (at least 0.001)",
                valid="fewer refinements",
            )


def mu_plan(scene: SceneConfig, search: SearchConfig) -> float:
    """The friction coefficient every plan may use, search.friction_safety x scene.mu: the search's
    grasps and stances and the CITO friction cones alike."""
    return search.friction_safety * scene.mu


@dataclass(frozen=True)
class CitoConfig:
    """Contact-implicit trajectory optimization (paper Sec. III-B, III-C) and IPOPT."""

    knots_per_segment: int = 12  # M_hat, time steps per transition segment
    dt: float = 0.1  # s, collocation time step
    # Q diagonal, on (x m, y m, theta rad); theta's weight keeps the final orientation within a degree of the goal.
    weight_pose: tuple[float, float, float] = (100.0, 100.0, 300.0)
    weight_torque: float = 1.0  # R = weight_torque * I, on tau (N m)
    weight_force: float = 0.01  # L = weight_force * I, on lambda (N)
    weight_slack: float = 100.0  # L1 penalty on the complementarity slacks gamma (eqs. 5-6), per unit slack
    # L1 penalty on the slacks of the plan's contact-point equalities (eqs. 12-15, TrajectoTree only), per m,
    # large enough that the equalities hold.
    weight_contact_slack: float = 1.0e4
    # Regularization (not in the paper): sum of squared accelerations, which IPOPT's L-BFGS needs to
    # converge; the fewest iterations before the contact-point slacks grow. 0 disables it.
    weight_acceleration: float = 3e-2
    # 1/m, log-sum-exp sharpness of the smooth box distance, sharp because it over-estimates the distance
    # near corners by up to log(2)/k (0.7 mm here), where a switching fingertip may cut the corner.
    sdf_sharpness: float = 1000.0
    # m, TrajectoTree only (not in the paper; configs/paper.yaml sets 0): the switching finger keeps
    # at least switch_clearance sin(pi j / M_hat) between fingertip and box at its segment's j-th
    # knot, and while lifted its normal force is bounded to 0 (it cannot push across the gap), so the
    # optimum cannot skim the box and push it from a distance, which the physics check refuses.
    switch_clearance: float = 0.01
    # Link rows (cito/links.py, not in the paper; configs/paper.yaml turns them off): at every knot
    # whose pose or joints are free, points on each finger's link collision boxes keep the box's
    # half width plus link_clearance off the object, and the object's vertices keep link_clearance
    # off each link-2 box (smooth distances; never more than the program's fixed end knots, the
    # search's nodes, have), because the fingertip spheres alone let links pass through the object.
    link_rows: bool = True  # false: only the fingertip spheres see the object (the paper)
    # Keyframes: each segment is first solved without the link rows, and again with them (from the
    # plan's guess) only when a link then overlaps the object (the physics check's exact test), since
    # most segments never bring a link near it and the rows cost iterations. false: in every segment
    # program from the start.
    link_rows_on_demand: bool = True
    # m, the link rows' margin, so that a link the rows hold off the object does not end up touching it.
    link_clearance: float = 0.001
    # IPOPT tol, on the scaled optimality error, loose because constraints are held to constr_viol_tol regardless.
    tol: float = 1e-3
    constr_viol_tol: float = 1e-6  # IPOPT constr_viol_tol
    acceptable_tol: float = 1e-1  # IPOPT acceptable_tol
    acceptable_constr_viol_tol: float = 1e-6  # IPOPT acceptable_constr_viol_tol
    acceptable_iter: int = 5  # IPOPT acceptable_iter
    max_iter: int = 1000  # IPOPT max_iter
    lbfgs_history: int = 6  # IPOPT limited_memory_max_history (fewer iterations than a shorter history)
    print_level: int = 0  # IPOPT print_level (0 silent, 5 verbose)
    formulation: str = "keyframes"  # TrajectoTree: a program per segment between the search's nodes, or "joint" (paper)

    def __post_init__(self):
        check_integer("cito.knots_per_segment", self.knots_per_segment, 2, 200)
        check_range("cito.dt", self.dt, 0.0, 1.0, low_open=True)
        check_length("cito.weight_pose", self.weight_pose, 3, "on x, y, theta")
        for i, v in enumerate(self.weight_pose):
            check_range("cito.weight_pose", v, 0.0, None, index=(i,))
        for name in ("weight_torque", "weight_force", "weight_slack", "weight_contact_slack", "weight_acceleration"):
            check_range(f"cito.{name}", getattr(self, name), 0.0, None)
        check_range("cito.sdf_sharpness", self.sdf_sharpness, 10.0, 1e5)
        check_range("cito.switch_clearance", self.switch_clearance, 0.0, 0.05)
        for name in ("link_rows", "link_rows_on_demand"):
            check_bool(f"cito.{name}", getattr(self, name))
        check_range("cito.link_clearance", self.link_clearance, 0.0, 0.02)
        for name in ("tol", "constr_viol_tol", "acceptable_tol", "acceptable_constr_viol_tol"):
            check_range(f"cito.{name}", getattr(self, name), 0.0, 1.0, low_open=True)
        check_integer("cito.acceptable_iter", self.acceptable_iter, 0)
        check_integer("cito.max_iter", self.max_iter, 1)
        check_integer("cito.lbfgs_history", self.lbfgs_history, 1, 100)
        check_integer("cito.print_level", self.print_level, 0, 12)
        if self.formulation not in FORMULATIONS:
            raise ConfigError(
                field="cito.formulation", value=self.formulation, problem="is unknown", choices=FORMULATIONS
            )


@dataclass(frozen=True)
class ControllerGains:
    """Both executors (same gains for every method): the fingertip impedance controller
    of paper eq. 20 (`kp`, `kv`) and the object-level GraspController (the rest)."""

    # Eq. 20, tuned on TrajectoTree plans; kv must stay below ~2 m_tip / sim.time_step for the discrete
    # plant to stay stable.
    kp: float = 400.0  # N/m, fingertip position stiffness
    kv: float = 5.0  # N s/m, fingertip velocity damping
    # GraspController: strong object gains with soft fingertip springs, which hold grasps that stiff
    # springs anchored to the measured box lose.
    rate_hz: float = 500.0  # Hz, control rate (torques are held between updates)
    object_kp: float = 2000.0  # s^-2, box pose error -> desired acceleration (x, y and theta alike)
    object_kd: float = 80.0  # s^-1, box velocity error -> desired acceleration
    tip_kp: float = 50.0  # N/m, fingertip spring to its target on the measured box (x (1 - force budget))
    tip_kd: float = 3.0  # N s/m, fingertip damping to its target's velocity
    min_normal_force: float = 0.1  # N, least push of a finger in contact (grasp-force QP)
    # N, most push of a finger in contact (grasp-force QP): room above a plan's squeeze, and near the
    # 1 N m motor limit at the fingers' reach.
    max_normal_force: float = 8.0
    # 1, weight of the box-wrench residual (N; torques divided by the box half-diagonal) in the QP,
    # relative to the deviation of the finger forces from the plan's (N), large so that the QP
    # squeezes harder to turn the box back rather than keep the plan's forces.
    wrench_weight: float = 1e4
    # 1, the grasp-force QP's friction cones use max(search.friction_safety, this) x scene.mu (0.56 by
    # default, looser than the plan's 0.49), because a sphere sticking to the box rolls where the plan
    # keeps its contact fixed, so executed stances need more friction than the plan's.
    friction_safety: float = 0.8
    ramp_time: float = 0.1  # s, a switching finger's force budget ramps to 0 after lift-off (back before landing)
    swing_lift: float = 0.008  # m, least fingertip gap mid-swing (its planned path, lifted where lower)
    contact_distance: float = 1e-3  # m, a planned fingertip this close to the planned box is in contact
    # GraspController: the motors also drive the fingers' own links (mass matrix, Coriolis, joint damping). Off by
    # default: on Drake's gripper (with min_normal_force 1.5 N) it ends 10 of 12 goals within 3e-4 rad but drops the
    # other 2 (docs/results.md).
    hand_dynamics: bool = False
    # The closed loop (simulate --closed-loop, trajectotree.execution.closed_loop): the contact watch, the
    # friction and mass estimates the grasp QP then uses, and the push reflex. Unused in open loop.
    slip_speed: float = 0.005  # m/s, a contact whose tangential velocity at the contact point exceeds this slides
    slip_min_force: float = 0.05  # N, a contact pushing less is not watched for slip (touch-downs, lift-offs)
    slip_confirm_time: float = 0.01  # s, a contact must slide this long before its ratio |f_t|/f_n counts
    # N, and push at least this hard: in Drake's lagged contact model lighter contacts slide below the world's
    # friction (8 nominal runs at mu 0.7: steady slides under 0.4 N read 0.32-0.68, above it 0.71)
    friction_evidence_force: float = 0.4
    # m, and only while the box is this close to the plan (position, and theta error x the box's circumradius): slides
    # of a box already off the plan read 0.26-0.38 in worlds of 0.3-0.4 (8 plans), the first ones 0.30-0.40
    friction_evidence_error: float = 0.005
    friction_floor: float = 0.2  # 1, the friction estimate (only ever lowered, by slides) never goes below this
    # s, the grasp QP's cones follow the friction estimate with this time constant (0: at once): a cone that fell from
    # 0.56 to 0.24 in one step moved every finger's force at once and spun the 50 g box off its grasp
    cone_time_constant: float = 0.1
    mass_accel_max: float = 0.5  # m/s^2, the fingers' vertical force measures the mass while |box accel| < this
    mass_time_constant: float = 0.2  # s, low-pass time constant of the mass estimate
    mass_estimate_range: tuple[float, float] = (0.25, 4.0)  # 1, the mass estimate / planned mass stays within this
    # N, a force on the box that neither the fingers' measured forces nor gravity explain (m a - f - m g) starts
    # the reflex when it lasts reflex_confirm_time
    reflex_force: float = 1.0
    reflex_confirm_time: float = 0.004  # s
    # N, during the reflex the grasp QP's target push of each holding finger rises to this (<= max_normal_force): a
    # target, not a bound, for a finger whose face turns along the push would push the box with it (a bound of 2 N
    # cost a 3-finger grasp 1.3 N of its 3.6 N against a +x push, and the box)
    reflex_squeeze: float = 2.0
    reflex_gain: float = 4.0  # 1, object_kp x this during the reflex (object_kd x its square root)
    reflex_hold: float = 0.2  # s, the reflex stays on this long after its trigger ends
    reflex_release: float = 0.2  # s, then fades back to the plan's gains and squeeze over this
    # 1, the fraction of the measured disturbance (PushReflex's) that the desired box wrench cancels at once: the
    # feedback alone answered a 3 N push only after the box had moved and turned
    disturbance_feedforward: float = 1.0
    # 1, the grasp QP's weight on the box torque residual x this during the reflex: a grasp short of force spends it
    # along the push rather than let the box turn
    reflex_torque_weight: float = 10.0
    # 1, the grasp QP's cones at max(friction_safety, this) x the friction estimate during the reflex: at 0.8 a
    # three-finger grasp held at most 2.9 N against +x (3.8 N at 1.0), short of a 3 N push
    reflex_friction_safety: float = 1.0
    # The landing reflex (closed loop): while a push is on or the friction estimate is land_friction_drop below the
    # plan's, a swinging finger runs its planned box-frame path land_speedup x as fast to its next planned landing
    # (tip spring land_tip_kp, land_tip_kd), and holds there until the plan gets there: the grasp gets all its fingers
    land_speedup: float = 20.0  # 1, how much faster a swing runs (1: no landing reflex)
    land_friction_drop: float = 0.05  # 1
    land_approach_time: float = 0.1  # s of the plan, the end of the path to the landing, run land_approach_speedup x
    land_approach_speedup: float = 4.0  # 1
    land_lag: float = 0.02  # m, the path's sample waits while the fingertip is farther than this from its target
    land_tip_kp: float = 400.0  # N/m
    land_tip_kd: float = 5.0  # N s/m

    def __post_init__(self):
        check_range("controller.rate_hz", self.rate_hz, 10.0, 10000.0)
        for name in ("kp", "kv", "object_kp", "object_kd", "tip_kp", "tip_kd", "min_normal_force", "wrench_weight"):
            check_range(f"controller.{name}", getattr(self, name), 0.0, None)
        check_range("controller.max_normal_force", self.max_normal_force, self.min_normal_force, None, low_open=True)
        check_range("controller.friction_safety", self.friction_safety, 0.0, 1.0, low_open=True)
        check_range("controller.ramp_time", self.ramp_time, 0.0, 2.0)
        check_range("controller.swing_lift", self.swing_lift, 0.0, 0.05)
        check_range("controller.contact_distance", self.contact_distance, 0.0, 0.02, low_open=True)
        check_range("controller.slip_speed", self.slip_speed, 0.0, 1.0, low_open=True)
        check_range("controller.slip_min_force", self.slip_min_force, 0.0, self.max_normal_force)
        check_range("controller.slip_confirm_time", self.slip_confirm_time, 0.0, 1.0)
        check_range("controller.friction_evidence_force", self.friction_evidence_force, 0.0, self.max_normal_force)
        check_range("controller.friction_evidence_error", self.friction_evidence_error, 0.0, 1.0, low_open=True)
        check_range("controller.friction_floor", self.friction_floor, 0.0, 1.0, low_open=True)
        check_range("controller.cone_time_constant", self.cone_time_constant, 0.0, 10.0)
        check_range("controller.mass_accel_max", self.mass_accel_max, 0.0, 100.0, low_open=True)
        check_range("controller.mass_time_constant", self.mass_time_constant, 0.0, 100.0, low_open=True)
        check_length("controller.mass_estimate_range", self.mass_estimate_range, 2, "low, high")
        low, high = self.mass_estimate_range
        check_range("controller.mass_estimate_range", low, 0.0, 1.0, low_open=True, index=(0,))
        check_range("controller.mass_estimate_range", high, 1.0, 100.0, index=(1,))
        check_range("controller.reflex_force", self.reflex_force, 0.0, None, low_open=True)
        check_range("controller.reflex_confirm_time", self.reflex_confirm_time, 0.0, 1.0)
        check_range("controller.reflex_squeeze", self.reflex_squeeze, 0.0, self.max_normal_force)
        check_range("controller.reflex_gain", self.reflex_gain, 1.0, 100.0)
        check_range("controller.reflex_hold", self.reflex_hold, 0.0, 10.0)
        check_range("controller.reflex_release", self.reflex_release, 0.0, 10.0)
        check_range("controller.disturbance_feedforward", self.disturbance_feedforward, 0.0, 1.0)
        check_range("controller.reflex_torque_weight", self.reflex_torque_weight, 1.0, 1e4)
        check_range("controller.reflex_friction_safety", self.reflex_friction_safety, 0.0, 1.0, low_open=True)
        check_range("controller.land_speedup", self.land_speedup, 1.0, 100.0)
        check_range("controller.land_friction_drop", self.land_friction_drop, 0.0, 1.0, low_open=True)
        check_range("controller.land_approach_time", self.land_approach_time, 0.0, 2.0)
        check_range("controller.land_lag", self.land_lag, 0.0, 0.1, low_open=True)
        check_range("controller.land_approach_speedup", self.land_approach_speedup, 1.0, 100.0)
        for name in ("land_tip_kp", "land_tip_kd"):
            check_range(f"controller.{name}", getattr(self, name), 0.0, None)


CONTROLLERS = ("grasp", "paper")  # sim.controller values: object-level grasp control, paper eq. 20
FORMULATIONS = (
    "keyframes",
    "joint",
)  # cito.formulation values: trajectotree.planning.keyframes, the paper's one program


def check_controller(value: str, name: str = "controller") -> str:
    """`value` if it names an executor; ConfigError naming `name` (the field or option) otherwise."""
    if value not in CONTROLLERS:
        raise ConfigError(field=name, value=value, problem="is not a controller", choices=CONTROLLERS)
    return value


@dataclass(frozen=True)
class ReplanConfig:
    """When the closed loop plans again from the measured state (simulate --replan); checked at
    the plan's nodes, where every finger holds the object at rest."""

    theta_error: float = 0.05  # rad, tracking error in orientation past which the plan no longer holds (~3 deg)
    position_error: float = 0.005  # m, the same in position: 10x what a tracked plan shows
    friction_drop: float = 0.05  # the friction estimate this far below the plan's scene.mu: its stances may slip
    mass_change: float = 0.2  # 1, a mass estimate this far (relative) from the plan's: its forces are wrong
    max_replans: int = 4  # per run, so a task the hand cannot do ends rather than replans forever
    # s, wall-clock budget of a replan's contact search (its search.time_budget_s): the hand holds while it
    # runs, and a search without a plan by then is refused (the old plan goes on)
    search_deadline_s: float = 0.5
    # s, the new plan's first segment must be solved (all its attempts) this long after the state was
    # measured, the search included, or it is refused too: the hand holds no longer than about this, less
    # than a segment lasts (cito.knots_per_segment x cito.dt, 1.2 s)
    first_segment_deadline_s: float = 1.0

    def __post_init__(self):
        check_range("sim.replan.theta_error", self.theta_error, 0.0, math.pi, low_open=True)
        check_range("sim.replan.position_error", self.position_error, 0.0, 0.05, low_open=True)
        check_range("sim.replan.friction_drop", self.friction_drop, 0.0, 1.0, low_open=True)
        check_range("sim.replan.mass_change", self.mass_change, 0.0, 10.0, low_open=True)
        check_integer("sim.replan.max_replans", self.max_replans, 0, 100)
        check_range("sim.replan.search_deadline_s", self.search_deadline_s, 0.0, 60.0, low_open=True)
        check_range("sim.replan.first_segment_deadline_s", self.first_segment_deadline_s, 0.0, 600.0, low_open=True)


@dataclass(frozen=True)
class SimConfig:
    """Full-dynamics execution in a discrete MultibodyPlant."""

    time_step: float = 1e-3  # s, discrete plant step
    settle_time: float = 0.5  # s, simulated after the plan ends (the last reference is held)
    drop_distance: float = 0.05  # m, the box is dropped once its position is this far from the plan
    log_period: float = 0.01  # s, sampling period of the logged box pose and hand state (metrics use it)
    controller: str = "grasp"  # executor: "grasp" (GraspController) or "paper" (eq. 20, ImpedanceController)
    push_duration: float = 0.2  # s, how long a push (simulate --push) acts on the box
    replan: ReplanConfig = field(default_factory=ReplanConfig)  # when simulate --replan plans again

    def __post_init__(self):
        check_range("sim.time_step", self.time_step, 0.0, 0.01, low_open=True)
        check_range("sim.settle_time", self.settle_time, 0.0, 10.0)
        check_range("sim.drop_distance", self.drop_distance, 0.0, 1.0, low_open=True)
        check_range("sim.log_period", self.log_period, self.time_step, 1.0)
        check_controller(self.controller, "sim.controller")
        check_range("sim.push_duration", self.push_duration, 0.0, 10.0, low_open=True)


@dataclass(frozen=True)
class GoalPose:
    """The pose in W the object is to end at: orientation theta (rad, any real number within
    +-MAX_GOAL_ROTATION: 2 pi is one full turn, -3 pi one and a half the other way) and position
    (x, y) (m; None: the start's, as a rotation goal). results.check_goal checks one; in a config
    file (its goal section) theta None means the file sets no goal."""

    theta: float | None = None
    position: tuple[float, float] | None = None

    def __post_init__(self):
        if self.theta is not None:
            check_goal_rotation("goal.theta", self.theta)
        if self.position is not None:
            check_length("goal.position", self.position, 2, "x m, y m")
            for i, v in enumerate(self.position):
                check_range("goal.position", v, -1.0, 1.0, index=(i,))  # m, as scene.initial_pose

    def pose(self, start) -> tuple[float, float, float]:
        """(x, y, theta) of this goal for an object starting at pose `start` (x, y, theta)."""
        x, y = (float(start[0]), float(start[1])) if self.position is None else self.position
        return (x, y, float(self.theta))

    def to_json(self) -> dict:
        return {"theta": self.theta, "position": None if self.position is None else list(self.position)}


# The bound as messages state it: 20 pi in 8 decimals rounded down, so that the printed bound is within it.
GOAL_ROTATION_BOUND = f"[-20 pi, 20 pi] rad, 20 pi = {math.floor(MAX_GOAL_ROTATION * 1e8) / 1e8:.8f}"


def check_goal_rotation(name: str, value, index: tuple[int, ...] = ()) -> float:
    """A goal orientation (rad): a finite number within +-MAX_GOAL_ROTATION; ConfigError naming
    `name` otherwise (results.check_goal, the one check of a whole goal, uses it)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or abs(value) > MAX_GOAL_ROTATION + 1e-9
    ):
        raise ConfigError(field=name, index=index, value=value, valid=GOAL_ROTATION_BOUND)
    return float(value)


def segments_for(search: SearchConfig, start, goal: GoalPose) -> int:
    """The transition segments S of the path from pose `start` to `goal`: search.num_nodes - 1 when
    it is set, else enough that the first min_segments turn the object by first_rotation at most
    and each further one by max_segment_rotation, and each moves it by max_segment_translation at
    most. ConfigError when that is more than MAX_NODES - 1."""
    if search.num_nodes is not None:
        return search.num_nodes - 1
    x, y, theta = goal.pose(start)
    turn = abs(theta - float(start[2]))
    shift = math.hypot(x - float(start[0]), y - float(start[1]))
    beyond = max(turn - search.first_rotation, 0.0) / search.max_segment_rotation
    segments = max(
        search.min_segments + math.ceil(beyond - 1e-9),  # a rotation of exactly k steps takes k, not k + 1
        math.ceil(shift / search.max_segment_translation - 1e-9),
    )
    if segments > MAX_NODES - 1:
        raise ConfigError(
            field="search.num_nodes",
            value=segments + 1,
            shown=f"{segments + 1} (for a goal {turn:.4g} rad and {shift:.4g} m from the start)",
            problem=f"would be needed at search.max_segment_rotation {search.max_segment_rotation:g} rad and "
            f"search.max_segment_translation {search.max_segment_translation:g} m",
            valid=f"at most {MAX_NODES} nodes: larger segment limits, or search.num_nodes",
        )
    return segments


def with_segments(search: SearchConfig, start, goal: GoalPose) -> SearchConfig:
    """`search` with num_nodes set for the path from `start` to `goal` (segments_for)."""
    return dc.replace(search, num_nodes=segments_for(search, start, goal) + 1)


@dataclass(frozen=True)
class Config:
    """Everything one trial uses; saved into every plan.json."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    search: SearchConfig = field(default_factory=SearchConfig)
    cito: CitoConfig = field(default_factory=CitoConfig)
    controller: ControllerGains = field(default_factory=ControllerGains)
    sim: SimConfig = field(default_factory=SimConfig)
    # the task's goal when a config file gives it (the CLI's --goal and --goal-pose override it); a
    # plan's config holds the goal it was planned for
    goal: GoalPose = field(default_factory=GoalPose)


def _load_section(cls, data, name: str, where: str):
    """Section `name` (dataclass `cls`) from its mapping `data` (None: the defaults)."""
    if data is None:
        return cls()
    if not isinstance(data, dict):
        raise ConfigError(f"{where} section {name} must be a mapping, got {data!r}")
    try:
        loaded = load_typed(cls, data)
    except DRAKE_ERRORS:  # Drake's message may name only the value: load key by key to name the key
        hints = typing.get_type_hints(cls)
        for key, value in data.items():
            try:
                load_typed(cls, {key: value})
            except DRAKE_ERRORS as e:
                kind = hints.get(key)
                kind = kind.__name__ if isinstance(kind, type) else kind  # float, tuple[float, float, float]
                why = f"valid keys: {list(hints)}" if kind is None else f"expected {kind}"
                raise ConfigError(f"{where}: {name}.{key} = {value!r}: {e}; {why}") from None
        raise
    return freeze(cls, loaded)


def config_from_dict(data: dict, where: str = "config") -> Config:
    """A Config from nested dicts (from YAML, plan.json or a sweep manifest); each section is
    loaded alone, so an error names its section. `where` names the source in messages."""
    if data is None:
        return Config()
    if not isinstance(data, dict):
        raise ConfigError(f"{where} must be a mapping, got {data!r}")
    sections = {f.name: f.default_factory for f in dc.fields(Config)}
    unknown = sorted(set(data) - set(sections))
    if unknown:
        raise ConfigError(f"unknown key(s) {unknown} in {where}; valid keys: {sorted(sections)}")
    return Config(**{name: _load_section(sections[name], value, name, where) for name, value in data.items()})


def config_to_dict(config: Config) -> dict:
    """Plain nested dicts (tuples as lists), suitable for JSON and YAML."""
    return dc.asdict(thaw(config))


def load_config(path: str | Path) -> Config:
    """Reads a YAML file; missing keys keep their defaults, unknown keys are errors."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"config file {str(path)!r} is a folder; give a YAML file")
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    try:
        data = drake_yaml().yaml_load_data(path.read_text())
    except UnicodeDecodeError as e:
        raise ConfigError(
            f"config file {str(path)!r} is not a text file (byte {e.start} is not UTF-8); give a YAML file"
        ) from None
    except yaml.YAMLError as e:
        raise ConfigError(f"config file {str(path)!r} is not valid YAML: {e}") from None
    if data is None:  # empty, comments only or null: more often a file not yet written than a wish for defaults
        raise ConfigError(
            f"config file {str(path)!r} holds no settings (it is empty, or only comments or null); write the "
            "fields to change, {} for the defaults, or give no config file"
        )
    return config_from_dict(data, f"config file {str(path)!r}")


def save_config(config: Config, path: str | Path) -> None:
    """Writes every field as YAML (Drake's yaml_dump_typed); `load_config` reads it back equal."""
    drake_yaml().yaml_dump_typed(thaw(config), filename=str(path))
