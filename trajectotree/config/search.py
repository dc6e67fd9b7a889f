"""The contact-sequence search's configuration (SearchConfig) and the goal it plans for (GoalPose),
with the segments a path from the start to a goal takes."""

from __future__ import annotations

import dataclasses as dc
import math
from dataclasses import dataclass

from trajectotree.config.checks import (
    MAX_FORCE,
    ConfigError,
    check_bool,
    check_integer,
    check_length,
    check_range,
)
from trajectotree.config.scene import SceneConfig

MAX_GOAL_ROTATION = 20 * math.pi  # rad, the largest goal rotation either way: ten turns
BUDGET_CLOCKS = ("cpu", "wall")  # search.budget_clock
STANCE_MARGINS = ("none", "prefer", "require")  # search.space_stance_margin
MAX_NODES = 400  # search.num_nodes at most: a ten-turn goal takes 238 with the default segment rotations


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
    # 1, the fraction of the motors' limit (tau_max, 0.396 N m on fingerpro4) within which the search in space's
    # stances (a root's four fingers, each transition's holders at their planned and rolled contacts) must hold the
    # cube at its planned mass: the rest is the closed loop's headroom for a heavier cube than planned (a stance's
    # torque grows about in proportion to the weight; the plane's search does not use it). 1.0: no headroom, the
    # default: 0.8 alone, and 0.67 with space_stance_friction_safety, lost plans (docs/measurements.md, as below).
    space_torque_fraction: float = 1.0
    # How the search in space uses the stance margin (space_stance_friction_safety): "none", its stances hold the cube
    # within the motors (space_torque_fraction) at mu_plan, as before the margin; "require", only stances that hold it
    # with their friction cones at the margin are kept; "prefer", such stances first, then those at the fallback's
    # friction (space_stance_fallback_safety), then those that hold only at mu_plan (children and roots ordered so),
    # searched in passes (space_margin_first_share), so a goal keeps a plan wherever "none" has one. The closure tests
    # and CITO's cones keep mu_plan in every mode. On the 30 seed-0 SO(3) goals, closed loop, friction 0.4 / mass x1.5
    # dropped: none 26/30 and 3/30; prefer 3/30 and 0/30, every goal planned and held nominally (docs/measurements.md
    # "Issue 37's acceptance on the default"); require leaves goals without a plan. The plane ignores it.
    space_stance_margin: str = "prefer"
    # 1, the margin's friction as a fraction of scene.mu (at most mu_plan): 0.4571 (about 16/35) x 0.7 = 0.32, the
    # friction the closed loop's grasp QP gives its cones where the world has 0.4 (controller.grasp.friction_safety
    # 0.8 x the estimate 0.4), so a stance that meets it is one that QP can make within the motors there. At 0.5714
    # (0.4, the world's own) the plans whose every stance met it still dropped at friction 0.4: their swings' stances
    # needed 0.35-0.37 and the QP's cones allowed 0.32 (docs/measurements.md "Why plans at the margin drop").
    # Used with space_stance_margin prefer and require only.
    space_stance_friction_safety: float = 0.4571
    # 1, with space_stance_margin prefer: a stance under the margin that holds the cube within the motors with its
    # cones at this fraction of scene.mu (0.5714 x 0.7 = 0.4, the slippery world's own friction) comes before one that
    # holds only at mu_plan, and the search's second pass adds such stances to the margin's (_SpaceSearch.passes);
    # ignored where not between the margin's friction and mu_plan. Goals 7 and 8 of seed 0 have no plan at the margin
    # within the first pass: their plans at 0.4 held at friction 0.4, those that took stances at mu_plan dropped.
    space_stance_fallback_safety: float = 0.5714
    # 1, in [0, 1): the share of the search's budgets (max_expansions, space_time_budget_s) in which
    # space_stance_margin prefer first searches margin stances alone, as require does, then each later pass with the
    # next friction's stances too, of the budgets the passes before it left (at 0.5 they end at 60, 90 and 120 s):
    # a greedy pass alone (0) turns to a stance under the margin at the first node without a margin child, so its
    # plans kept about half their stances at the margin (docs/measurements.md "The stance margin as a preference");
    # plans of every stance at 0.4 took 17-29 s of CPU on 6 of the 30 seed-0 SO(3) goals ("A longer margin pass in
    # space").
    space_margin_first_share: float = 0.5
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
    # node budget of the search from one initial grasp (of each window of it): no plan of the 76 box goals (60 seed-0,
    # 16 held-out) needs more than 823 from its root, while goal +3.021's two fruitless 0.01 m roots spent 2000 each
    # (6.2 s of search, 4.1 s at 1000); 1000 left every plan of those, the other hands' and the five polygons'
    # seed-0 goals unchanged (docs/measurements.md "Initial grasps", scripts/compare_root_expansions.py).
    root_expansions: int = 1000
    # Segments one depth-first search looks ahead: the paper's 9, so a path of up to 9 segments is
    # searched as Algorithm 1 does; a longer one window by window (trajectotree.search.tree), which
    # keeps its search time linear in its length.
    window_segments: int = 9
    # Segments of a window's path kept before the next window is searched from their end, each kept
    # node chosen seeing the 4 beyond it (3, 4 and 6 took 10-35 % more expansions on 8 long goals).
    commit_segments: int = 5
    max_expansions: int = 20000  # node budget of the search (all initial grasps together)
    time_budget_s: float = 30.0  # s, budget of the search in the plane, on budget_clock
    # s, budget of the search in space, on budget_clock (its time_budget_s; space_margin_first_share of it for margin
    # stances alone): 4x the plane's, because a plan whose every stance holds at 0.4 or less took 30-70 s of CPU on
    # goals 1 and 27 of the 30 seed-0 SO(3) goals, and with stances at mu_plan both dropped in a world the plan did not
    # assume (docs/measurements.md "A longer margin pass in space").
    space_time_budget_s: float = 120.0
    # what the budget counts: "cpu", the search thread's CPU seconds (a loaded machine plans what a quiet one does: at
    # load 7 the wall clock ran out on 13 of the 23 axis-aligned goals that plan at load 4), or "wall", the wall clock
    # (the replanner's deadline: the simulated world does not wait for the planner)
    budget_clock: str = "cpu"
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
        check_range("search.min_closure_margin", self.min_closure_margin, 0.0, MAX_FORCE)
        check_range("search.friction_safety", self.friction_safety, 0.0, 1.0, low_open=True)
        check_bool("search.rolled_stances", self.rolled_stances)
        check_range("search.rolled_corner_gap", self.rolled_corner_gap, 0.0, 0.05)
        check_range("search.space_torque_fraction", self.space_torque_fraction, 0.0, 1.0, low_open=True)
        check_range("search.space_stance_friction_safety", self.space_stance_friction_safety, 0.0, 1.0, low_open=True)
        check_range("search.space_stance_fallback_safety", self.space_stance_fallback_safety, 0.0, 1.0, low_open=True)
        check_range("search.space_margin_first_share", self.space_margin_first_share, 0.0, 1.0, high_open=True)
        if self.space_stance_margin not in STANCE_MARGINS:
            raise ConfigError(
                field="search.space_stance_margin",
                value=self.space_stance_margin,
                problem="is unknown",
                choices=STANCE_MARGINS,
            )
        check_range("search.finger_clearance", self.finger_clearance, 0.0, 0.05)
        check_range("search.max_stance_force", self.max_stance_force, 0.0, 1000.0)
        check_range("search.push_capacity", self.push_capacity, 0.0, 100.0)
        check_range("search.push_normal_force", self.push_normal_force, 0.0, 1000.0, low_open=True)
        check_range("search.initial_grid_step", self.initial_grid_step, 0.001, 0.1)
        check_integer("search.window_segments", self.window_segments, 1, 100)
        check_integer("search.commit_segments", self.commit_segments, 1, self.window_segments)
        for name in ("max_initial_grasps", "root_expansions", "max_expansions"):
            check_integer(f"search.{name}", getattr(self, name), 1)
        for name in ("time_budget_s", "space_time_budget_s"):
            check_range(f"search.{name}", getattr(self, name), 0.0, 86400.0, low_open=True)  # s, a day
        if self.budget_clock not in BUDGET_CLOCKS:
            raise ConfigError(
                field="search.budget_clock", value=self.budget_clock, problem="is unknown", choices=BUDGET_CLOCKS
            )
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
