"""The contact-sequence planner: the paper's Algorithm 1 (Sec. III-A).

A depth-first tree search over contact configurations along a fixed object path of N
poses (linear interpolation from the initial pose to the goal rotation). A node at depth
n holds the object pose x*_n, the four contacts (arclengths along the box boundary) and
the joint angles. Expanding a node (GetNeighbors) moves one free finger (the other three
alone are in frictional form closure) by a displacement from D_cp, or keeps every finger
(zero displacement), at pose x*_{n+1}. SelectNode takes the deepest open node, ties
broken by the paper's heuristic sum_i |q2_i - nominal_joint2|.

IsFeasible runs when a node is selected, as in Algorithm 1: frictional form closure (LP,
trajectotree.grasp) and reachability by Drake IK without the links entering the box
(trajectotree.reach). GetNeighbors already drops candidates that fail cheap exact tests
(corner margin, overlapping fingertips, closed-form reachability), so the LP and the IK
run only for nodes the search actually visits. States reached twice at the same depth are
inserted once (their subtrees are identical).

Two additions to the paper, neither of which changes which plans exist:
- Before the search, one vectorized closed-form pass per finger tabulates every contact
  the finger can ever hold (its initial arclength plus sums of displacements) at every
  depth: reachable or not, and q2 for the heuristic.
- From that table, the fewest contact switches each finger alone needs to the last node.
  Only one finger switches per step, so a node whose fingers together need more switches
  than steps remain is a dead end and is not inserted. Without this bound the DFS spends
  seconds in subtrees that cannot reach the goal (this hand reaches only ~0.15-0.2 m of
  the boundary from each base, so large rotations need most of the nine steps).
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass

import numpy as np

from trajectotree.config import ConfigError, SearchConfig
from trajectotree.contact_plan import ContactNode, ContactPlan, SearchStats
from trajectotree.geometry import BoxBoundary
from trajectotree.grasp import FormClosure
from trajectotree.reach import Reachability
from trajectotree.scene import NUM_FINGERS, Scene

# Default initial grasp, as fractions of the faces (see default_initial_arclengths).
DEFAULT_GRASP_FACE_FRACTIONS = ((3, 0.7), (1, 0.1), (2, 0.6), (3, 0.4))


def default_initial_arclengths(scene: Scene) -> np.ndarray:
    """The initial grasp used for every trial (paper Sec. IV-A: the same for all goals).

    As fractions of the faces: finger 0 (bottom right) on the bottom face at 0.7, finger 1
    (top right) on the top face at 0.1, finger 2 (top left) on the left face at 0.6, finger 3
    (bottom left) on the bottom face at 0.4; for the 0.20 x 0.10 m box the arclengths
    (0.54, 0.12, 0.36, 0.48) m, i.e. contacts at x = 0.04 and -0.02 below, x = 0.08 on top
    and y = -0.01 on the left. Why: the grasp is in frictional form closure with fingers 0, 2
    and 3 free (finger 1 is the only contact pushing down), every contact is reachable at both
    +-20 degrees (the first step of a +-pi goal), and the hand's fixed elbow branch makes
    reachability chiral, so the grasp must leave room for either direction: among the grasps
    whose contacts stay reachable over the first step, this one was found (by running the
    search on all 60 goals of seed 0) to admit a plan for every goal in [-pi, pi] with N = 10,
    without crowding two fingertips together. Fractions make it scale with the box size.
    """
    boundary = BoxBoundary(scene.config.box_width, scene.config.box_height)
    corners = boundary.corner_arclengths()
    lengths = np.diff(np.r_[corners, boundary.perimeter])
    return np.array([corners[face] + fraction * lengths[face] for face, fraction in DEFAULT_GRASP_FACE_FRACTIONS])


def object_path(initial_pose, goal: float, num_nodes: int) -> np.ndarray:
    """(N, 3) poses x*_n from the initial pose to the initial pose rotated by `goal`."""
    x0 = np.asarray(initial_pose, dtype=float)
    return x0 + np.outer(np.linspace(0.0, 1.0, num_nodes), [0.0, 0.0, goal])


@dataclass(frozen=True)
class _Node:
    depth: int
    arclengths: tuple[float, ...]
    switching_finger: int | None
    parent: "_Node | None"


class _Search:
    """One run of Algorithm 1; holds the LP and IK caches and the counters."""

    def __init__(self, scene: Scene, goal: float, config: SearchConfig):
        self.scene, self.config = scene, config
        self.boundary = BoxBoundary(scene.config.box_width, scene.config.box_height)
        self.poses = object_path(scene.config.initial_pose, goal, config.num_nodes)
        self.closure = FormClosure(self.boundary, scene.config.mu, config.min_closure_margin)
        self.reach = Reachability(scene)
        half = (config.num_displacements - 1) // 2
        self.displacements = config.displacement_step * np.arange(-half, half + 1)
        self.expanded = self.generated = 0
        self.min_switches: list[list[dict[float, float]]] = []  # [finger][depth][arclength] -> switches
        self.joint2: list[list[dict[float, float]]] = []  # [finger][depth][arclength] -> q2 (reachable only)
        self._moves: dict[float, list[float]] = {}

    def wrap(self, s: float) -> float:
        """The canonical arclength key: in [0, perimeter), rounded to 1e-9 m."""
        return round(float(s) % self.boundary.perimeter, 9)

    # -- per-finger grid and admissible pruning ------------------------------------------------
    def plan_switch_bounds(self, start) -> None:
        """Per finger, over the arclengths it can ever hold (its initial contact plus sums of
        displacements), which are corner-free and reachable (closed form, vectorized) at each
        depth, with their joint-2 angle for the heuristic; then the fewest contact switches
        that keep that finger alone on such contacts from each (depth, arclength) to the last
        node. A node whose fingers together need more switches than steps remain has no
        completion (one switch per step), so pruning it never removes a plan; it only spares
        the DFS hopeless subtrees."""
        last = self.config.num_nodes - 1
        corners, per = self.boundary.corner_arclengths(), self.boundary.perimeter
        for finger, s0 in enumerate(start):
            grid, frontier = {s0}, {s0}  # every arclength the finger can ever hold
            for _ in range(last):
                frontier = {m for s in frontier for m in self.moves(s)} - grid
                grid |= frontier
            grid = np.array(sorted(grid))
            gap = np.abs(grid[:, None] - corners[None, :])
            corner_free = np.min(np.minimum(gap, per - gap), axis=1) >= self.scene.config.corner_margin
            # reachability of the whole grid at every depth in one vectorized call
            q2 = self.reach.closed_form_many(np.repeat(self.poses[1:], len(grid), axis=0), finger,
                                             np.tile(grid, last))[:, 1].reshape(last, len(grid))
            allowed = [dict(zip(grid[ok].tolist(), row[ok].tolist()))
                       for row in q2 for ok in [corner_free & np.isfinite(row)]]
            layers = [{s0: np.nan}]
            for depth in range(1, last + 1):  # forward: contacts reachable from s0 by displacements
                candidates = {m for s in layers[-1] for m in self.moves(s)}
                layers.append({s: allowed[depth - 1][s] for s in candidates if s in allowed[depth - 1]})
            cost = [dict.fromkeys(layers[last], 0)]
            for depth in range(last - 1, -1, -1):  # backward: fewest switches to the end
                after, here = cost[0], {}
                for s in layers[depth]:
                    here[s] = min(after.get(s, np.inf), 1 + min(after.get(m, np.inf) for m in self.moves(s)))
                cost.insert(0, here)
            self.joint2.append(layers)
            self.min_switches.append(cost)

    def moves(self, s: float) -> list[float]:
        """The arclengths s + d for every d in D_cp (wrapped keys), memoized."""
        if s not in self._moves:
            self._moves[s] = [self.wrap(s + d) for d in self.displacements]
        return self._moves[s]

    def switches_needed(self, depth: int, arclengths) -> float:
        return sum(self.min_switches[i][depth].get(s, np.inf) for i, s in enumerate(arclengths))

    # -- IsFeasible -----------------------------------------------------------------------
    def contacts_allowed(self, arclengths) -> str:
        """Why these contacts are not allowed on the boundary ("" when they are)."""
        margin = self.scene.config.corner_margin
        if any(self.boundary.corner_distance(s) < margin for s in arclengths):
            return f"a contact lies within {margin} m of a corner"
        if any(self.tips_overlap(arclengths, i) for i in range(NUM_FINGERS)):
            return "two fingertips overlap"
        return ""

    def tips_overlap(self, arclengths, finger: int) -> bool:
        """Finger `finger`'s fingertip sphere would overlap another finger's."""
        r = self.reach.tip_radius
        p, n = self.reach.contact(arclengths[finger])
        return any(np.linalg.norm(p + r * n - q - r * m) < 2 * r
                   for i, (q, m) in enumerate(map(self.reach.contact, arclengths)) if i != finger)

    def infeasibility(self, node: _Node) -> str:
        """Why `node` is a dead end ("" when it is feasible): closure LP, then Drake IK."""
        closure = self.closure.check(node.arclengths)
        if not closure.in_closure:
            return f"not in frictional form closure (margin {closure.margin:.3g})"
        pose = self.poses[node.depth]
        for i, s in enumerate(node.arclengths):
            reach = self.reach.solve(pose, i, s)
            if not reach.reachable:
                return f"finger {i} cannot reach its contact: {reach.reason}"
        return ""

    # -- GetNeighbors ---------------------------------------------------------------------
    def neighbors(self, node: _Node):
        """(heuristic, child) for each candidate child that passes the cheap exact tests."""
        free = [i for i in range(NUM_FINGERS) if self.closure.is_free(node.arclengths, i)]
        if not free:
            return []
        candidates = {node.arclengths: None}  # the zero displacement: no finger moves
        for i in free:
            for s in self.moves(node.arclengths[i]):
                if s != node.arclengths[i]:
                    moved = list(node.arclengths)
                    moved[i] = s
                    candidates.setdefault(tuple(moved), i)
        out, steps_left, depth = [], self.config.num_nodes - 2 - node.depth, node.depth + 1
        for arclengths, finger in candidates.items():
            q2 = [self.joint2[i][depth].get(s) for i, s in enumerate(arclengths)]
            if None in q2 or self.switches_needed(depth, arclengths) > steps_left:
                continue  # a finger cannot reach (closed form), or no completion exists
            if finger is not None and self.tips_overlap(arclengths, finger):
                continue
            h = sum(abs(v - self.config.nominal_joint2) for v in q2)  # the paper's heuristic
            out.append((h, _Node(depth, arclengths, finger, node)))
        return out

    # -- Algorithm 1 ----------------------------------------------------------------------
    def run(self, start: tuple[float, ...], t0: float) -> tuple[_Node | None, str]:
        reason = self.contacts_allowed(start)
        if reason:
            return None, f"initial grasp not allowed: {reason}"
        root = _Node(0, start, None, None)
        dead_end = self.infeasibility(root)
        if dead_end:
            return None, f"initial grasp infeasible: {dead_end}"
        self.plan_switch_bounds(start)
        needed = self.switches_needed(0, start)
        if not np.isfinite(needed):
            return None, "some finger has no reachable, corner-free contact at every node of the object path"
        if needed > self.config.num_nodes - 1:
            return None, (f"the goal needs at least {int(needed)} contact switches (each finger must stay on reachable "
                          f"contacts), more than the {self.config.num_nodes - 1} steps of {self.config.num_nodes} nodes")
        counter = itertools.count()
        open_set = [(0, 0.0, next(counter), root)]
        inserted = {(0, start)}
        goal_depth = self.config.num_nodes - 1
        last_dead_end = ""
        while open_set:
            if self.expanded >= self.config.max_expansions:
                return None, f"node budget exhausted ({self.config.max_expansions} expansions)"
            if time.perf_counter() - t0 > self.config.time_budget_s:
                return None, f"time budget exhausted ({self.config.time_budget_s} s)"
            *_, node = heapq.heappop(open_set)  # SelectNode: deepest, then lowest heuristic
            self.expanded += 1
            dead_end = self.infeasibility(node)
            if dead_end:
                last_dead_end = dead_end
                continue
            if node.depth == goal_depth:
                return node, ""
            for h, child in self.neighbors(node):
                if (child.depth, child.arclengths) not in inserted:
                    inserted.add((child.depth, child.arclengths))
                    self.generated += 1
                    heapq.heappush(open_set, (-child.depth, h, next(counter), child))
        return None, ("no contact sequence reaches the goal in "
                      f"{self.config.num_nodes} nodes (tree exhausted; last dead end: {last_dead_end or 'none'})")

    def contact_node(self, node: _Node) -> ContactNode:
        pose = self.poses[node.depth]
        points = [self.reach.contact(s) for s in node.arclengths]
        q = np.concatenate([self.reach.solve(pose, i, s).q for i, s in enumerate(node.arclengths)])
        return ContactNode(object_pose=pose.copy(), q=q, arclengths=np.array(node.arclengths),
                           p_BC=np.array([p for p, _ in points]), n_B=np.array([n for _, n in points]),
                           switching_finger=node.switching_finger,
                           closure_margin=self.closure.check(node.arclengths).margin)

    def stats(self, t0: float) -> SearchStats:
        return SearchStats(expanded=self.expanded, generated=self.generated, lp_calls=self.closure.lp_calls,
                           ik_calls=self.reach.ik_calls, time_s=time.perf_counter() - t0)


def find_contact_plan(scene: Scene, goal: float, config: SearchConfig) -> ContactPlan:
    """Algorithm 1 for the rotation `goal` (rad) of scene's box: N nodes from the initial
    grasp (node 0) to the goal pose, each in frictional form closure and reachable, with
    at most one finger changing contact between consecutive nodes. A search that finds no
    plan within the budgets returns success=False with the reason."""
    if not np.isfinite(goal):
        raise ConfigError(f"goal = {goal!r} is not a finite number; valid range: [-pi, pi] rad")
    t0 = time.perf_counter()
    search = _Search(scene, float(goal), config)
    initial = config.initial_arclengths if config.initial_arclengths is not None else default_initial_arclengths(scene)
    start = tuple(search.wrap(s) for s in initial)
    leaf, reason = search.run(start, t0)
    if leaf is None:
        return ContactPlan(goal=float(goal), success=False, reason=reason, stats=search.stats(t0))
    path = []
    while leaf is not None:
        path.append(leaf)
        leaf = leaf.parent
    nodes = tuple(search.contact_node(n) for n in reversed(path))
    return ContactPlan(goal=float(goal), success=True, reason="", nodes=nodes, stats=search.stats(t0))
