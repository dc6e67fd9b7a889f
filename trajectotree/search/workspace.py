"""Where the hand can hold the object: the poses at which it has an initial grasp.

A pose is graspable when the hand has an initial grasp there as trajectotree.search.initial_grasp
defines one: one grid contact per finger (every search.initial_grid_step of arclength, each at least
scene.corner_margin from a corner), each reachable by its finger at that pose (closed-form IK with
the link collision test), no two fingertip spheres overlapping, and the other contacts of some
finger that may let go needing less friction than mu_plan (their required_mu, bisected as the
table's ranking does). Closure and overlap depend on the contacts alone, so they are tabulated once
for every triple of grid contacts; each pose then costs one reach test per finger.

The workspace of a goal pose (x, y, theta) is checked along its path: every node pose of the search's
object path (trajectotree.search.tree.object_path) must be graspable, since the search needs a grasp
at each. `trajectotree scene` reports the translations of the start, on a grid, that are graspable at
every orientation (sampled every WORKSPACE_ORIENTATION_STEP over a full turn), so any rotation, however
many turns, may be combined with them, and those graspable at the start orientation.

Graspable is not turnable: a hand whose fingers reach little of the object may hold it at every
orientation yet not gait it round. `rotation_range` (`trajectotree scene --rotations`) runs the
contact search itself for goal rotations every ROTATION_STEP outwards from the start, each way.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from trajectotree.config import ConfigError, GoalPose, SearchConfig, mu_plan, segments_for
from trajectotree.scene.plant import Scene
from trajectotree.search.grasp import required_mu_many
from trajectotree.search.initial_grasp import RANKING_BISECTIONS, GraspTables, stance_fingers
from trajectotree.search.reach import Reachability
from trajectotree.search.tree import find_contact_plan, object_path

WORKSPACE_STEP = 0.01  # m, spacing of the translations the scene report tests
WORKSPACE_REACH = 0.15  # m, the farthest translation it tests along x and y (the fingers reach ~0.2 m)
WORKSPACE_ORIENTATION_STEP = math.pi / 18  # rad, the orientations it tests: every 10 degrees of a full turn


class Graspability:
    """Whether the hand has an initial grasp of scene's object at given poses (module doc);
    the contact tables are built once, for the poses of any number of queries."""

    def __init__(self, scene: Scene, search: SearchConfig, reach: Reachability | None = None):
        c = scene.config
        self.num_fingers = scene.num_fingers
        k = self.num_fingers - 1  # contacts of a stance: all fingers but the one that lets go
        self.reach = reach or Reachability(scene)
        boundary = c.shape
        grid = np.round(np.arange(0.0, boundary.perimeter - 1e-9, search.initial_grid_step), 9)
        self.grid = grid[[boundary.corner_distance(s) >= c.corner_margin for s in grid]]
        p, n = boundary.points(self.grid)
        tips = p + self.reach.tip_radius * n
        gap = np.linalg.norm(tips[:, None] - tips[None, :], axis=2)
        self.apart = gap >= 2 * self.reach.tip_radius  # (G, G), as initial_grasp's overlap filter
        G = len(self.grid)
        sets = np.array(list(itertools.combinations(range(G), k)), dtype=int).reshape(-1, k)
        for a, b in itertools.combinations(range(k), 2):
            sets = sets[self.apart[sets[:, a], sets[:, b]]]
        mus = required_mu_many(p[sets], n[sets], bisections=RANKING_BISECTIONS) if len(sets) else []
        self.holds = np.zeros((G,) * k, dtype=bool)  # k contacts that hold the object at mu_plan, in any order
        held = sets[np.asarray(mus) < mu_plan(c, search)]
        for perm in itertools.permutations(range(k)):
            self.holds[tuple(held[:, m] for m in perm)] = True

    def reachable(self, poses: np.ndarray) -> np.ndarray:
        """(P, F, G) bool: which grid contacts each finger reaches at each pose (P, 3)."""
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        G = len(self.grid)
        out = np.empty((len(poses), self.num_fingers, G), dtype=bool)
        every_pose, every_contact = np.repeat(poses, G, axis=0), np.tile(self.grid, len(poses))
        for i in range(self.num_fingers):
            q = self.reach.closed_form_many(every_pose, i, every_contact)
            out[:, i] = np.isfinite(q[:, 0]).reshape(len(poses), G)
        return out

    def at(self, poses: np.ndarray) -> np.ndarray:
        """(P,) bool: the hand has an initial grasp at each pose (P, 3)."""
        return np.array([self._grasp_exists(r) for r in self.reachable(poses)], dtype=bool)

    def _grasp_exists(self, reachable: np.ndarray) -> bool:
        """Some finger may let go of some grasp of the reachable contacts (F, G)."""
        lists = [np.flatnonzero(r) for r in reachable]
        if any(len(s) == 0 for s in lists):
            return False
        for i, others in enumerate(stance_fingers(self.num_fingers)):
            held = np.argwhere(self.holds[np.ix_(*(lists[j] for j in others))])
            if not len(held):
                continue
            stance = np.stack([lists[j][held[:, m]] for m, j in enumerate(others)], axis=1)  # (h, F - 1)
            free = self.apart[lists[i]][:, stance]  # (len, h, F - 1): the free finger's contact apart from each
            if np.any(free.all(axis=2)):
                return True
        return False


@dataclass(frozen=True)
class Workspace:
    """The translations of the start (dx, dy) on a grid at which the hand has an initial grasp."""

    step: float  # m, the grid's spacing
    orientations: int  # orientations tested over a full turn (every 2 pi / orientations rad)
    every_orientation: np.ndarray  # (K, 2) m, translations graspable at every tested orientation
    start_orientation: np.ndarray  # (L, 2) m, translations graspable at the start orientation

    @staticmethod
    def radius(points: np.ndarray, step: float) -> float:
        """m, the largest distance r from the start such that every grid translation within r is
        among `points` (0 when the start itself is not): the distance of the last one, nearest
        first, before the first missing one."""
        have = {(round(x / step), round(y / step)) for x, y in points}
        k = round(WORKSPACE_REACH / step)
        grid = sorted((math.hypot(i, j), (i, j)) for i in range(-k, k + 1) for j in range(-k, k + 1))
        r = 0.0
        for distance, ij in grid:
            if ij not in have:
                break
            r = distance * step
        else:
            return float(k * step)  # the whole tested square: at least this far
        return float(r) if (0, 0) in have else 0.0

    def to_json(self) -> dict:
        def region(points: np.ndarray) -> dict:
            return {
                "radius_m": self.radius(points, self.step),
                "points": len(points),
                "x_range_m": [float(points[:, 0].min()), float(points[:, 0].max())] if len(points) else None,
                "y_range_m": [float(points[:, 1].min()), float(points[:, 1].max())] if len(points) else None,
                "translations_m": points.round(6).tolist(),
            }

        return {
            "grid_step_m": self.step,
            "orientations": self.orientations,
            "every_orientation": region(self.every_orientation),
            "start_orientation": region(self.start_orientation),
        }


def workspace(scene: Scene, search: SearchConfig, grasp: Graspability | None = None) -> Workspace:
    """scene's workspace about its initial pose (module doc), on the WORKSPACE_STEP grid within
    WORKSPACE_REACH along x and y."""
    grasp = grasp or Graspability(scene, search)
    x0 = np.asarray(scene.config.initial_pose, dtype=float)
    axis = np.arange(-WORKSPACE_REACH, WORKSPACE_REACH + WORKSPACE_STEP / 2, WORKSPACE_STEP).round(9)
    shifts = np.array([(dx, dy) for dx in axis for dy in axis])
    count = round(2 * math.pi / WORKSPACE_ORIENTATION_STEP)
    turns = x0[2] + WORKSPACE_ORIENTATION_STEP * np.arange(count)  # the start orientation first
    at_start = grasp.at(np.column_stack([x0[:2] + shifts, np.full(len(shifts), x0[2])]))
    alive = at_start.copy()
    for theta in turns[1:]:  # only translations graspable so far are tested at the next orientation
        rows = np.flatnonzero(alive)
        if not len(rows):
            break
        alive[rows] = grasp.at(np.column_stack([x0[:2] + shifts[rows], np.full(len(rows), theta)]))
    return Workspace(WORKSPACE_STEP, count, shifts[alive], shifts[at_start])


GOAL_LIMIT_STEP = 0.002  # m, how finely a refused goal position's limit is stated


def check_goal_position(
    scene: Scene,
    search: SearchConfig,
    goal: GoalPose,
    name: str = "goal.position",
    grasp: Graspability | None = None,
    start=None,
) -> None:
    """ConfigError (before any planning) when `goal` moves the object where the hand cannot carry
    it: some node pose of the search's path to it (search.num_nodes, or from the distance) is not
    graspable. The error names the node and states the limit: how far the start may be moved in the
    goal's direction, with its rotation, every node of the path staying graspable. The path starts
    at `start` (x, y, theta; None: scene.initial_pose). A goal without a position passes."""
    if goal.position is None:
        return
    grasp = grasp or Graspability(scene, search)
    x0 = np.asarray(scene.config.initial_pose if start is None else start, dtype=float)

    def refused_node(distance: float) -> int | None:
        shift = np.asarray(goal.position) - x0[:2]
        towards = shift * (distance / np.linalg.norm(shift)) if distance else np.zeros(2)
        moved = GoalPose(theta=goal.theta, position=tuple(x0[:2] + towards))
        poses = object_path(x0, moved, segments_for(search, x0, moved) + 1)
        ok = grasp.at(poses)
        return None if ok.all() else int(np.argmin(ok))

    node = refused_node(float(np.hypot(*(np.asarray(goal.position) - x0[:2]))))
    if node is None:
        return
    limit = 0.0
    distance = float(np.hypot(*(np.asarray(goal.position) - x0[:2])))
    for d in np.arange(GOAL_LIMIT_STEP, distance, GOAL_LIMIT_STEP):
        if refused_node(float(d)) is not None:
            break
        limit = float(d)
    poses = object_path(x0, goal, segments_for(search, x0, goal) + 1)
    x, y, theta = poses[node]
    raise ConfigError(
        field=name,
        value=goal.position,
        shown=f"({goal.position[0]:g}, {goal.position[1]:g}) m",
        problem=f"is outside the hand's workspace: along the path to it the hand has no grasp of the object at "
        f"node {node} of {len(poses)} (pose x {x:+.4f} m, y {y:+.4f} m, theta {theta:+.4f} rad)",
        valid=f"at most {limit:.3g} m from the start ({x0[0]:g}, {x0[1]:g}) m in this direction with this rotation",
        label="valid",
    )


ROTATION_STEP = math.pi / 36  # rad, the goal rotations rotation_range tests: every 5 degrees
ROTATION_LIMIT = math.pi  # rad, the farthest it tests each way (a hand that gaits turns further: --goal takes 20 pi)


@dataclass(frozen=True)
class RotationRange:
    """The goal rotations (of the object in place, from scene.initial_pose) for which the contact
    search finds a contact sequence, tested outwards from 0 every `step` rad each way until the
    first that has none or `limit`."""

    step: float  # rad
    limit: float  # rad, the farthest tested each way
    ccw: float  # rad >= 0, every tested rotation in (0, ccw] has a contact sequence
    cw: float  # rad >= 0, every tested rotation in [-cw, 0) has one
    refused: tuple[float | None, float | None]  # rad, the first counter-clockwise / clockwise without one (None: none)

    @property
    def symmetric(self) -> float:
        """rad, the largest R with every tested rotation in [-R, R] planned: min(ccw, cw)."""
        return min(self.ccw, self.cw)

    def to_json(self) -> dict:
        return {
            "step_rad": self.step,
            "limit_rad": self.limit,
            "ccw_rad": self.ccw,
            "cw_rad": self.cw,
            "symmetric_rad": self.symmetric,
            "first_refused_rad": list(self.refused),
        }


def rotation_range(
    scene: Scene, search: SearchConfig, step: float = ROTATION_STEP, limit: float = ROTATION_LIMIT
) -> RotationRange:
    """scene's RotationRange: the contact search (tree.find_contact_plan, search's settings) for
    goals +-step, +-2 step, ... outwards, each way until the first without a contact sequence."""
    tables, theta0 = GraspTables(), float(scene.config.initial_pose[2])
    reach, refused = [], []
    for sign in (1.0, -1.0):
        last, first_refused = 0.0, None
        for k in range(1, int(round(limit / step)) + 1):
            turn = min(k * step, limit)
            if not find_contact_plan(scene, theta0 + sign * turn, search, tables).success:
                first_refused = sign * turn
                break
            last = turn
        reach.append(last)
        refused.append(first_refused)
    return RotationRange(step=step, limit=limit, ccw=reach[0], cw=reach[1], refused=(refused[0], refused[1]))
