"""The contact-sequence planner in the plane: the paper's Algorithm 1 (Sec. III-A); in space: search.space_tree.

A depth-first tree search over contact configurations along a fixed object path of N
poses (linear interpolation from the initial pose to the goal rotation). A node at depth
n holds the object pose x*_n, the four contacts (arclengths along the object's boundary, any
convex polygon, trajectotree.geometry) and
the joint angles. Expanding a node (GetNeighbors) moves one free finger (the other three
alone are in frictional form closure) by a displacement from D_cp, or keeps every finger
(zero displacement), at pose x*_{n+1}. SelectNode takes the deepest open node, ties
broken by the paper's heuristic sum_i |q2_i - nominal_joint2|.

IsFeasible runs when a node is selected, as in Algorithm 1: frictional form closure (LP,
trajectotree.search.grasp) and reachability by Drake IK without the links entering the object
(trajectotree.search.reach), and (not in the paper) no two fingers within search.finger_clearance
of each other at the node's joint angles nor on the straight joint-space path from its parent's.
GetNeighbors already drops candidates that fail cheap exact tests (corner margin, overlapping
fingertips, closed-form reachability), so the LP and the IK run only for nodes the search
actually visits. States reached twice at the same depth are
inserted once (their subtrees are identical), except one refused for the fingers' path from its
parent, which another parent may still reach (_refuses_the_move).

Two additions to the paper, neither of which changes which plans exist:
- Before the search, a table per finger of every contact it can ever hold at every depth
  (reachable, q2 for the heuristic) and, from it, the fewest contact switches it alone needs
  to the last node; a node whose fingers together need more switches than steps remain is
  not inserted (trajectotree.search.switch_bound).
- A finger whose contact leaves reach at the next pose must be the one that moves (two
  such fingers: no child); at a root, the k-th earliest such deadline must be node k or later.

Friction margin (not in the paper, whose setting is search.friction_safety = 1):
every LP uses mu_plan = friction_safety x scene.mu, so every node's grasp and every
three-finger stance held while a finger switches (is_free) is in frictional form closure
with friction to spare. Each plan node reports `required_mu` (its grasp) and
`stance_required_mu` (the three fingers that held the box while it was reached).

Stance checks (trajectotree.search.stance; not in the paper): each three-finger stance that holds the
object while a finger switches (all four when none does) must also be in closure at mu_plan, and
short of the corners, where its sticking fingertips roll to (search.rolled_stances), and must
carry the object's weight with at most search.max_stance_force newtons of total normal force at
its planned contacts.

Push order (trajectotree.search.stance; not in the paper): among the children of a node, SelectNode
takes first those whose holding fingers resist a push of search.push_capacity newtons along each of
+-x and +-y (an LP at mu_plan within each finger's force bound and its motors), the others by how
far short they fall, and only then by the paper's heuristic. It orders the same tree, so it finds a
plan wherever the paper's order does (within the same budgets), but not the same plan.

Initial grasp: unless search.initial_arclengths is given, the search is rooted at the
ranked candidates of trajectotree.search.initial_grasp, best first; a candidate whose fingers
cannot reach the goal with one switch per step (the bound above) is skipped without a
search, and each searched candidate gets at most search.root_expansions expansions, up to
search.max_initial_grasps candidates. States found dead from one root stay dead for the next.

Contact grid (not in the paper): contacts lie on a grid of arclengths, the initial grid plus
multiples of the displacement step. When its first root yields no plan, a grid halved
search.grid_refinements times (grid_levels) is searched too, the grids taking turns, one root
each, coarsest first, within the same budgets. Short faces need it: the 0.14 m triangle's faces
hold six 0.02 m grid points (none at a face's middle, where the three normals meet): at mu_plan
0.49 the search finds no plan on that grid for 3 of its 12 seed-0 goals, and one for all 12 on
the 0.01 m grid. So do fingers kept apart (search.finger_clearance) on the default box: two
fingertips (10 mm) on one face sit 20 or 40 mm apart on the 0.02 m grid, 30 mm on the 0.01 m one,
and five of the 60 seed-0 goals (2.59-3.12 rad) have no plan from 200 of the coarse grid's roots
(3500-6000 expansions) while the fine grid's first or third root has one. Why turns rather than
the whole coarse grid first: the coarse grid's later roots rarely succeed where its first failed.
A plan from the coarse grid's first root is unchanged.
"""

from __future__ import annotations

import itertools
import math
import time
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from trajectotree.config import ConfigError, GoalPose, SearchConfig, mu_plan, with_segments
from trajectotree.contact_plan import ContactNode, ContactPlan, SearchStats
from trajectotree.refusal import AtRoot, NoPlan, Refusal, RefusalKind, SearchRefusal, on_grids
from trajectotree.results import check_goal
from trajectotree.scene.finger_clearance import (
    FingerCapsules,
    FingerShapes,
    finger_shapes,
    fingers_clear,
    shapes_pair_distances,
)
from trajectotree.scene.plant import Scene
from trajectotree.search.grasp import FormClosure
from trajectotree.search.initial_grasp import GraspTables, initial_grasp_candidates, stance_fingers
from trajectotree.search.reach import Reachability, path_refusal
from trajectotree.search.stance import StanceChecks, arclength_key
from trajectotree.search.switch_bound import SwitchBound


@dataclass(frozen=True)
class SearchClock:
    """When a search started: by the wall clock (the time it reports) and by the clock its budget counts
    (search.budget_clock: "cpu", the search thread's CPU seconds, so a loaded machine plans as a quiet one; "wall",
    for the replanner, whose world does not wait)."""

    wall: float  # s, time.perf_counter() at the start
    budget: float  # s, the budget's clock at the start
    cpu: bool  # the budget counts this thread's CPU time

    @classmethod
    def start(cls, config: SearchConfig) -> SearchClock:
        cpu = config.budget_clock == "cpu"
        return cls(time.perf_counter(), time.thread_time() if cpu else time.perf_counter(), cpu)

    def over(self, config: SearchConfig) -> bool:
        """The search has spent more than config.time_budget_s on its budget's clock."""
        now = time.thread_time() if self.cpu else time.perf_counter()
        return now - self.budget > config.time_budget_s

    def elapsed(self) -> float:
        """s of wall clock since the start."""
        return time.perf_counter() - self.wall


def object_path(initial_pose, goal: GoalPose | float, num_nodes: int) -> np.ndarray:
    """(N, 3) poses x*_n from the initial pose to `goal`, linearly interpolated in x, y and theta:
    a GoalPose, or an orientation (rad in W) at the same position."""
    x0 = np.asarray(initial_pose, dtype=float)
    goal = goal if isinstance(goal, GoalPose) else GoalPose(theta=float(goal))
    return x0 + np.outer(np.linspace(0.0, 1.0, num_nodes), np.asarray(goal.pose(x0)) - x0)


@dataclass(frozen=True)
class _Node:
    depth: int
    arclengths: tuple[float, ...]
    switching_finger: int | None
    parent: _Node | None


class _Search:
    """One run of Algorithm 1; holds the LP and IK caches and the counters."""

    def __init__(self, scene: Scene, goal, config: SearchConfig):
        goal = check_goal(goal)
        config = with_segments(config, scene.config.initial_pose, goal)
        self.scene, self.config, self.goal = scene, config, goal
        self.boundary = scene.config.shape
        self.poses = object_path(scene.config.initial_pose, goal, config.num_nodes)
        self.mu_plan = mu_plan(scene.config, config)
        self.closure = FormClosure(self.boundary, self.mu_plan, config.min_closure_margin)
        self.reach = Reachability(scene)
        self.capsules = FingerCapsules.of(scene.fingers, self.reach.tip_radius)  # the path tests' bounds
        self.bound = SwitchBound(scene, self.reach, self.poses, config)
        self.stance = StanceChecks(
            scene,
            self.reach,
            self.poses,
            self.mu_plan,
            config.max_stance_force,
            angles=self.bound.angles,
            corner_gap=config.rolled_corner_gap,
            push_normal_force=config.push_normal_force,
        )
        self.refused: Counter[Refusal] = Counter()  # why moves were not generated (coarse), for NoPlan
        self.dead: set[tuple] = set()  # (depth, arclengths) whose subtree was searched without a plan
        self.expanded = self.generated = self.backups = 0
        self.overlaps: dict[tuple[float, float], bool] = {}  # (s, t) -> tips_overlap's pair test
        self.gaps: dict[tuple, float] = {}  # (depth, i, s_i, j, s_j) -> m, two fingers' distance at a node
        self.shapes: dict[tuple, FingerShapes] = {}  # (depth, i, s_i) -> finger i's shapes at a node
        # [finger][depth][arclength] -> q2 (reachable only) / fewest switches to the end; s + D_cp
        self.joint2, self.min_switches, self.moves = self.bound.joint2, self.bound.min_switches, self.bound.moves

    def wrap(self, s: float) -> float:
        """The canonical arclength key: in [0, perimeter), rounded to 1e-9 m."""
        return arclength_key(self.boundary.perimeter, s)

    def plan_switch_bounds(self, starts) -> None:
        """Tabulates each finger's contacts and fewest switches from `starts` (its initial
        arclengths, one set per finger; trajectotree.search.switch_bound)."""
        self.bound.plan(starts)

    # -- IsFeasible -----------------------------------------------------------------------
    def contacts_allowed(self, arclengths) -> Refusal | None:
        """Why these contacts are not allowed on the boundary (None when they are)."""
        margin = self.scene.config.corner_margin
        if not np.all(self.boundary.corner_free(arclengths, margin)):
            return Refusal(RefusalKind.CORNER, limit=margin)
        if any(self.tips_overlap(arclengths, i) for i in range(self.scene.num_fingers)):
            return Refusal(RefusalKind.TIPS_OVERLAP)
        return None

    def tips_overlap(self, arclengths, finger: int) -> bool:
        """Finger `finger`'s fingertip sphere would overlap another finger's."""
        s = arclengths[finger]
        return any(self.tip_overlaps(s, t) for i, t in enumerate(arclengths) if i != finger)

    def tip_overlaps(self, s: float, t: float) -> bool:
        """A fingertip sphere touching the object at arclength s overlaps one touching it at t
        (memoized by the ordered pair: the distance is computed from s's side, as tips that just
        touch sit at the threshold)."""
        hit = self.overlaps.get((s, t))
        if hit is None:
            r = self.reach.tip_radius
            (p, n), (q, m) = self.reach.contact(s), self.reach.contact(t)
            hit = self.overlaps[(s, t)] = bool(np.linalg.norm(p + r * n - q - r * m) < 2 * r)
        return hit

    def infeasibility(self, node: _Node) -> Refusal | None:
        """Why `node` is a dead end (None when it is feasible): closure LP, then Drake IK."""
        return self.not_in_closure(node.arclengths) or self.unreachable(node)

    def not_in_closure(self, arclengths) -> Refusal | None:
        closure = self.closure.check(arclengths)
        if not closure.in_closure:
            return Refusal(
                RefusalKind.NOT_IN_CLOSURE,
                mu_plan=self.mu_plan,
                margin=closure.margin,
                required_mu=self.closure.required_mu(arclengths),
            )
        return None

    def unreachable(self, node: _Node) -> Refusal | None:
        """Why a finger of `node` cannot reach its contact, or two fingers collide there or on the
        straight joint-space path from its parent (None when neither)."""
        q = self.joints(node)
        if isinstance(q, Refusal):
            return q
        return self.fingers_refused(node, q)

    def fingers_refused(self, node: _Node, q: np.ndarray) -> Refusal | None:
        """FINGERS_COLLIDE when two fingers come within search.finger_clearance of each other at the
        node's joint angles q (2F,), or on the straight joint-space path from its parent's (count 1);
        None when neither. The node's pair distances are memoized by depth and the two fingers'
        contacts (`gaps`: its siblings share the pairs of the fingers that do not move); the path is
        sampled for the pairs it could bring that close only (reach.path_refusal)."""
        fingers, r, clearance = self.scene.fingers, self.reach.tip_radius, self.config.finger_clearance
        keys = self.gap_keys(node)
        missing = [pair for pair, key in keys.items() if key not in self.gaps]
        shapes = {i: self.finger_shapes(node, i, q) for i in sorted({i for pair in missing for i in pair})}
        for pair, d in shapes_pair_distances(shapes, missing, r).items():
            self.gaps[keys[pair]] = float(d[0])
        gaps = {pair: self.gaps[key] for pair, key in keys.items()}
        closest = min(gaps, key=gaps.get, default=None)
        if closest is not None and not fingers_clear(gaps[closest], clearance):
            return Refusal(RefusalKind.FINGERS_COLLIDE, fingers=closest, limit=clearance)
        if node.parent is None:
            return None
        parent = self.gap_keys(node.parent)  # the parent passed: all its gaps are known
        ends = {pair: (self.gaps[parent[pair]], gap) for pair, gap in gaps.items()}
        return path_refusal(fingers, self.joints(node.parent), q, r, clearance, ends, self.capsules)

    def finger_shapes(self, node: _Node, finger: int, q: np.ndarray) -> FingerShapes:
        """Finger `finger`'s collision shapes at the node's joint angles q (2F,), memoized by depth and
        its contact (`shapes`: the node's siblings share those of the fingers that do not move)."""
        key = (node.depth, finger, node.arclengths[finger])
        if key not in self.shapes:
            self.shapes[key] = finger_shapes(
                self.scene.fingers[finger], q[None, 2 * finger : 2 * finger + 2], self.reach.tip_radius
            )
        return self.shapes[key]

    def gap_keys(self, node: _Node) -> dict[tuple[int, int], tuple]:
        """{(i, j): the key of `gaps`} for each pair of fingers i < j of `node`."""
        return {
            (i, j): (node.depth, i, node.arclengths[i], j, node.arclengths[j])
            for i, j in itertools.combinations(range(self.scene.num_fingers), 2)
        }

    def joints(self, node: _Node) -> np.ndarray | Refusal:
        """The node's joint angles (2F,) by Drake IK (memoized per finger), or why a finger cannot reach."""
        pose, q = self.poses[node.depth], []
        for i, s in enumerate(node.arclengths):
            reach = self.reach.solve(pose, i, s, seed=self.bound.tabulated(node.depth, i, s))
            if not reach.reachable:
                return Refusal(RefusalKind.UNREACHABLE, fingers=(i,), cause=reach.refusal)
            q.append(reach.q)
        return np.concatenate(q)

    # -- GetNeighbors ---------------------------------------------------------------------
    def neighbors(self, node: _Node):
        """(switches it needs to the goal, heuristic, child) for each candidate child that passes the
        cheap exact tests (`siblings` orders them, with the push shortfall of their stances)."""
        depth = node.depth + 1
        # fingers whose contact is out of reach at the next pose must move now (same children,
        # fewer tests: with two of them there is no child at all)
        stuck = [i for i, s in enumerate(node.arclengths) if s not in self.joint2[i][depth]]
        if len(stuck) > 1:
            self.refused[Refusal(RefusalKind.CONTACTS_LOST, fingers=tuple(stuck))] += 1
            return []
        movers = stuck or list(range(self.scene.num_fingers))
        free = [i for i in movers if self.closure.is_free(node.arclengths, i)]
        held = RefusalKind.STUCK_FINGER_HELD if stuck else RefusalKind.FINGER_HELD
        for i in sorted(set(movers) - set(free)):
            self.refused[
                Refusal(held, fingers=(i,), stance=stance_fingers(self.scene.num_fingers)[i], mu_plan=self.mu_plan)
            ] += 1
        if not free:
            return []
        candidates = {} if stuck else {node.arclengths: None}  # the zero displacement: no finger moves
        for i in free:
            for s in self.moves(node.arclengths[i]):
                if s != node.arclengths[i]:
                    moved = list(node.arclengths)
                    moved[i] = s
                    candidates.setdefault(tuple(moved), i)
        out, steps_left, stances = [], self.config.num_nodes - 2 - node.depth, {}
        for arclengths, finger in candidates.items():
            q2 = [self.joint2[i][depth].get(s) for i, s in enumerate(arclengths)]
            if None in q2:  # the moved finger's new contact is out of reach (closed form) or at a corner
                self.refused[Refusal(RefusalKind.NEW_CONTACT_UNREACHABLE, fingers=(finger,))] += 1
                continue
            switches = self.bound.switches_needed(depth, arclengths)
            if switches > steps_left or not self.bound.deadlines_met(depth, arclengths):  # no completion exists
                self.refused[Refusal(RefusalKind.SWITCH_BOUND)] += 1
                continue
            if finger is not None and self.tips_overlap(arclengths, finger):
                self.refused[Refusal(RefusalKind.TIPS_OVERLAP)] += 1
                continue
            if finger not in stances:  # the stance depends on the finger (None: all hold), not on where it moves
                stances[finger] = self.stance_refused(node, depth, finger)
            if stances[finger]:
                self.refused[stances[finger]] += 1
                continue
            h = sum(abs(v - self.config.nominal_joint2) for v in q2)  # the paper's heuristic
            out.append((switches, h, _Node(depth, arclengths, finger, node)))
        return out

    def siblings(self, node: _Node, children, toward_goal: bool) -> _Siblings:
        """`node`'s children (neighbors' rows, those the tree takes) as the window's open set at their depth,
        in SelectNode's order: switches needed first when `toward_goal`, then their stance's push shortfall
        (push_shortfall), then the heuristic, then as generated."""
        rows = [(switches if toward_goal else 0, h, child) for switches, h, child in children]
        return _Siblings(rows, lambda finger: self.push_shortfall(node, node.depth + 1, finger))

    def push_shortfall(self, node: _Node, depth: int, finger: int | None) -> _Shortfall:
        """N by which the stance holding the object while `finger` moves from `node` to the child
        at `depth` falls short of resisting search.push_capacity (0 when it does, or when it is 0),
        its LPs solved as far as the order needs them."""
        return _Shortfall(self.config.push_capacity, self.stance.push_values(node, depth, finger))

    def stance_refused(self, node: _Node, depth: int, finger: int | None) -> Refusal | None:
        """Why the stance holding the object while `finger` moves from `node` to the child at
        `depth` is refused (None when it is not): its rolled contacts (search.rolled_stances),
        then the force it needs to hold the object (search.max_stance_force; trajectotree.search.stance).
        finger None: no finger moves and all hold, checked at their rolled contacts only (they roll
        as far in a segment without a switch)."""
        rolled = self.stance.rolled(node, depth, finger) if self.config.rolled_stances else None
        return rolled or (None if finger is None else self.stance.too_heavy(node, depth, finger))

    # -- Algorithm 1 ----------------------------------------------------------------------
    def precheck(self, start: tuple[float, ...], candidate: bool = False) -> Refusal | None:
        """Why the search from `start` cannot succeed, by cheap tests (None when it may). A
        `candidate` of trajectotree.search.initial_grasp already passed the contact tests (corners,
        overlap, closure), so the goal's table look-ups come first and its LP last."""
        if not candidate:
            refused = (None if self.config.measured_start else self.contacts_allowed(start)) or self.not_in_closure(
                start
            )
            if refused:
                return Refusal(RefusalKind.INITIAL_GRASP, cause=refused)
        per_finger = [self.min_switches[i][0].get(s, np.inf) for i, s in enumerate(start)]
        if not np.isfinite(sum(per_finger)):
            stuck = tuple(i for i, v in enumerate(per_finger) if not np.isfinite(v))
            return Refusal(RefusalKind.NO_PATH_CONTACTS, fingers=stuck)
        if sum(per_finger) > self.config.num_nodes - 1:
            return Refusal(
                RefusalKind.TOO_MANY_SWITCHES,
                count=int(sum(per_finger)),
                per_finger=tuple(int(v) for v in per_finger),
                limit=self.config.num_nodes - 1,
            )
        # Each finger must switch by the first node where its initial contact is out of reach;
        # one switch per node, so the k-th earliest such deadline must be at least node k.
        deadlines = sorted(
            (next((d for d in range(1, self.config.num_nodes) if s not in self.joint2[i][d]), np.inf), i)
            for i, s in enumerate(start)
        )  # inf: never needs to move
        for k, (deadline, _) in enumerate(deadlines, start=1):
            if deadline < k:
                late = tuple(i for d, i in deadlines[:k])
                return Refusal(RefusalKind.DEADLINES, fingers=late, count=int(deadline))
        dead_end = (self.not_in_closure(start) if candidate else None) or self.unreachable(_Node(0, start, None, None))
        return Refusal(RefusalKind.INITIAL_GRASP, cause=dead_end) if dead_end else None

    def run(
        self, start: tuple[float, ...], t0: SearchClock, budget: int, total: int
    ) -> tuple[_Node | None, Refusal | None]:
        """Algorithm 1 from the root `start` (precheck passed): one DFS to the goal with at most
        `budget` expansions when the path has at most search.window_segments segments, else
        window by window (module doc), each window with at most `budget` expansions and all of
        them with at most `total`."""
        goal_depth = self.config.num_nodes - 1
        committed = [_Node(0, start, None, None)]
        expanded0 = self.expanded
        why = None
        while committed:
            anchor = committed[-1]
            target = min(anchor.depth + self.config.window_segments, goal_depth)
            left = total - (self.expanded - expanded0)
            leaf, why = self.window(anchor, target, t0, min(budget, left), toward_goal=target < goal_depth)
            if leaf is not None and leaf.depth == goal_depth:
                return leaf, None
            if leaf is not None:  # keep the first commit_segments of its path, search on from there
                while leaf.depth > anchor.depth + self.config.commit_segments:
                    leaf = leaf.parent
                committed.append(leaf)
                continue
            if why.kind is RefusalKind.TIME_BUDGET or len(committed) == 1 or self.expanded - expanded0 >= total:
                return None, why
            # no window from here: back up one commit, this state (dead now) no longer reachable
            self.dead.add((anchor.depth, anchor.arclengths))
            committed.pop()
            self.backups += 1
        return None, why

    def window(
        self, anchor: _Node, target: int, t0: SearchClock, budget: int, toward_goal: bool
    ) -> tuple[_Node | None, Refusal | None]:
        """A node at depth `target` below `anchor` by Algorithm 1's DFS (SelectNode: deepest, then
        least push shortfall, then lowest heuristic), with at most `budget` expansions.
        `toward_goal` (a window short of the goal, which it cannot test): children needing fewer
        contact switches to the goal (switch_bound) come first, then the same order."""
        open_set = [_Siblings([(0, 0.0, anchor)], None)]  # one set of siblings per depth, the deepest last
        inserted = {(anchor.depth, anchor.arclengths)}
        expanded0 = self.expanded
        while open_set:
            if self.expanded - expanded0 >= budget:
                return None, Refusal(RefusalKind.NODE_BUDGET, count=budget)
            if t0.over(self.config):
                return None, Refusal(RefusalKind.TIME_BUDGET, limit=self.config.time_budget_s)
            node = open_set[-1].pop()  # SelectNode: the deepest open node
            if not open_set[-1]:
                open_set.pop()
            self.expanded += 1
            dead_end = self.infeasibility(node)
            if dead_end:
                self.refused[dead_end.coarse()] += 1
                if _refuses_the_move(dead_end):  # not the state: another parent may still reach it
                    inserted.discard((node.depth, node.arclengths))
                continue
            if node.depth == target:
                return node, None
            states = ((row, (row[2].depth, row[2].arclengths)) for row in self.neighbors(node))
            children = [row for row, state in states if state not in inserted and state not in self.dead]
            if children:
                inserted.update((child.depth, child.arclengths) for *_, child in children)
                self.generated += len(children)
                open_set.append(self.siblings(node, children, toward_goal))
        self.dead |= inserted  # the whole tree was searched: none of its states reaches `target`, nor the goal
        return None, Refusal(RefusalKind.TREE_EXHAUSTED, count=self.expanded - expanded0)

    def contact_nodes(self, path: list[_Node]) -> tuple[ContactNode, ...]:
        """The plan's nodes, with the required friction of each grasp and switching stance
        (both computed in one vectorized pass each)."""
        stances = [
            [s for i, s in enumerate(n.arclengths) if i != n.switching_finger]
            for n in path
            if n.switching_finger is not None
        ]
        grasp_mu = self.closure.required_mus([n.arclengths for n in path])
        stance_mu = iter(self.closure.required_mus(stances))
        pushes = [None] + [self.stance.push_capacity(a, b.depth, b.switching_finger) for a, b in zip(path, path[1:])]
        return tuple(
            self.contact_node(n, mu, None if n.switching_finger is None else next(stance_mu), push)
            for n, mu, push in zip(path, grasp_mu, pushes)
        )

    def contact_node(
        self, node: _Node, required_mu: float, stance_required_mu: float | None, stance_push_capacity: float | None
    ) -> ContactNode:
        pose = self.poses[node.depth]
        points = [self.reach.contact(s) for s in node.arclengths]
        q = np.concatenate([self.reach.solve(pose, i, s).q for i, s in enumerate(node.arclengths)])
        return ContactNode(
            object_pose=pose.copy(),
            q=q,
            arclengths=np.array(node.arclengths),
            p_BC=np.array([p for p, _ in points]),
            n_B=np.array([n for _, n in points]),
            switching_finger=node.switching_finger,
            closure_margin=self.closure.check(node.arclengths).margin,
            required_mu=required_mu,
            stance_required_mu=stance_required_mu,
            stance_push_capacity=None if stance_push_capacity == -np.inf else stance_push_capacity,
        )

    def stats(self, t0: SearchClock, roots: int = 0, candidates: int = 0) -> SearchStats:
        return SearchStats(
            expanded=self.expanded,
            generated=self.generated,
            lp_calls=self.closure.lp_calls,
            ik_calls=self.reach.ik_calls,
            time_s=t0.elapsed(),
            initial_grasps_searched=roots,
            initial_grasp_candidates=candidates,
        )


class _Shortfall:
    """A stance's push shortfall (N, _Search.push_shortfall) with its LP values (StanceChecks.push_values)
    solved one at a time as the order needs them: `lower` bounds it from below, and is it once `exact`."""

    def __init__(self, capacity: float, values):
        self.capacity, self.values = capacity, values
        self.least = math.inf  # N, the least of the values solved so far
        self.exact = not capacity  # no push asked for: 0

    def lower(self) -> float:
        return max(0.0, self.capacity - self.least)

    def refine(self) -> None:
        """Solves the next value (exact when none is left)."""
        value = next(self.values, None)
        if value is None:
            self.exact = True
        else:
            self.least = min(self.least, value)


class _Siblings:
    """The open children of one node, taken best first in SelectNode's order: (switches, push shortfall,
    heuristic, as generated), rows (switches, heuristic, child) given in the order generated. The window
    holds one such set per depth, the deepest last: the DFS takes the deepest open node, so while a node's
    children are open no other node's are at their depth, and its heap of old ordered every node by this
    key after its depth alone. Children of one finger share their stance's shortfall (`shortfall(finger)`, a
    _Shortfall), so it only orders children of different fingers, and is computed only as far as that
    needs: never with one finger, and of a finger that comes later only until its lower bound sets it behind."""

    def __init__(self, rows, shortfall):
        self.shortfall, self.shortfalls = shortfall, {}
        self.groups: dict[int | None, list] = {}  # finger -> its children's (switches, h, n, child), best last
        for n, (switches, h, child) in enumerate(rows):
            self.groups.setdefault(child.switching_finger, []).append((switches, h, n, child))
        for group in self.groups.values():
            group.sort(key=lambda row: row[:3], reverse=True)

    def __bool__(self) -> bool:
        return bool(self.groups)

    def pop(self) -> _Node:
        """The best child, taken out."""
        heads = {finger: group[-1] for finger, group in self.groups.items()}
        least = min(head[0] for head in heads.values())
        tied = [finger for finger, head in heads.items() if head[0] == least]
        while len(tied) > 1:
            for finger in tied:
                if finger not in self.shortfalls:
                    self.shortfalls[finger] = self.shortfall(finger)
            best = min(tied, key=lambda f: (self.shortfalls[f].lower(), *heads[f][1:3]))
            if self.shortfalls[best].exact:  # no other's shortfall can be below its lower bound
                tied = [best]
            else:
                self.shortfalls[best].refine()
        group = self.groups[tied[0]]
        *_, child = group.pop()
        if not group:
            del self.groups[tied[0]]
        return child


def _refuses_the_move(refusal: Refusal) -> bool:
    """Whether `refusal` is of the move into a node (its fingers collide on the way from its parent:
    FINGERS_COLLIDE with count 1), not of its state. Such a state is neither inserted (it may be
    generated again from a later parent, which the DFS expands only after every deeper node, this
    one included) nor dead for the next root."""
    return refusal.kind is RefusalKind.FINGERS_COLLIDE and bool(refusal.count)


class _Roots:
    """The initial grasps to try, best first, made search keys one by one as the search reaches them."""

    def __init__(self, arclengths: np.ndarray, num_fingers: int):
        self.arclengths = np.asarray(arclengths, dtype=float).reshape(-1, num_fingers)

    def __len__(self) -> int:
        return len(self.arclengths)

    def __iter__(self):
        return (tuple(self.arclengths[k].tolist()) for k in range(len(self.arclengths)))

    def per_finger(self) -> list[set[float]]:
        """Each finger's initial contacts over all roots (the switch-bound tables' starts)."""
        return [set(self.arclengths[:, i].tolist()) for i in range(self.arclengths.shape[1])]


def _roots(
    scene: Scene, config: SearchConfig, search: _Search, tables: GraspTables | None
) -> tuple[_Roots, Refusal | None]:
    """The initial grasps to try, best first: the user's, or the ranked candidates (from
    `tables` when given, else built here)."""
    if config.initial_arclengths is not None:
        if len(config.initial_arclengths) != scene.num_fingers:
            raise ConfigError(
                field="search.initial_arclengths",
                value=config.initial_arclengths,
                problem=f"has {len(config.initial_arclengths)} entries",
                valid=f"{scene.num_fingers}: one arclength (m) per finger of the hand",
            )
        return _Roots([[search.wrap(s) for s in config.initial_arclengths]], scene.num_fingers), None
    if tables is None:
        table = initial_grasp_candidates(scene, config, search.reach)
    else:
        table = tables.get(scene, config, search.reach)
    return _Roots(table.arclengths, scene.num_fingers), table.refusal  # grid values: already canonical keys


def grid_levels(config: SearchConfig) -> list[SearchConfig]:
    """The search settings of each contact grid, coarsest (the configured one) first, then
    search.grid_refinements times halved: initial_grid_step and displacement_step / 2,
    num_displacements 2 n - 1 (the same longest move); see the module doc for why."""
    levels = [config]
    for _ in range(config.grid_refinements):
        c = levels[-1]
        levels.append(
            replace(
                c,
                initial_grid_step=c.initial_grid_step / 2,
                displacement_step=c.displacement_step / 2,
                num_displacements=2 * c.num_displacements - 1,
            )
        )
    return levels


def choose_initial_grasp(
    scene: Scene, goal, config: SearchConfig, tables: GraspTables | None = None
) -> tuple[tuple[float, ...] | None, SearchRefusal | None]:
    """The chooser's first choice for `goal` without a tree search: config.initial_arclengths
    if given, else the best-ranked candidate that passes the cheap checks the search applies
    before rooting a tree at it (the per-finger switch bound for this goal, closure at mu_plan,
    Drake IK), on the coarsest grid (grid_levels) where one passes. The search may still end up
    rooted at a later candidate if this one's tree has no plan. (None, refusal) when no
    candidate passes."""
    goal = check_goal(goal)
    config = with_segments(config, scene.config.initial_pose, goal)
    refused = []
    for level in grid_levels(config):
        chosen, why = _choose_on_grid(scene, goal, level, tables)
        if chosen is not None:
            return chosen, None
        refused.append((level.displacement_step, why))
    return None, on_grids(refused)


def _choose_on_grid(
    scene: Scene, goal: GoalPose, config: SearchConfig, tables: GraspTables | None
) -> tuple[tuple[float, ...] | None, Refusal | None]:
    search = _Search(scene, goal, config)
    roots, refusal = _roots(scene, config, search, tables)
    if not roots:
        return None, refusal
    search.plan_switch_bounds(roots.per_finger())
    first = None
    for root in roots:
        why = search.precheck(root, candidate=config.initial_arclengths is None)
        if why is None:
            return root, None
        first = first or why
    return None, Refusal(RefusalKind.NO_ROOT_PASSES, count=len(roots), cause=first)


def find_contact_plan(scene: Scene, goal, config: SearchConfig, tables: GraspTables | None = None) -> ContactPlan:
    """Algorithm 1 for `goal` (results.check_goal: a rotation in rad, a pose (x, y, theta) or a
    GoalPose) of scene's object: N nodes (search.num_nodes, or from the goal's distance:
    config.segments_for) from the initial grasp (node 0) to the goal pose, each in frictional
    form closure at mu_plan and reachable, with at most one finger changing contact between consecutive nodes while the
    other three are in closure at mu_plan. The contact grids of grid_levels take turns, one
    searched root each, coarsest first, a finer grid's search set up when the coarser one's first
    root has no plan (module doc); the budgets (time, expansions) hold for all grids together.
    A search that finds no plan returns success=False with the refusal of each grid (which stance
    or reach failed). `tables` keeps the ranked initial grasps between searches (without it each
    search ranks them, inside its time)."""
    goal = check_goal(goal)
    config = with_segments(config, scene.config.initial_pose, goal)
    t0 = SearchClock.start(config)
    levels, grids = grid_levels(config), []
    while True:
        turned = False
        for n, level in enumerate(levels):
            left = config.max_expansions - sum(g.search.expanded for g in grids)
            if left <= 0 or t0.over(config):
                break
            if n == len(grids):
                grids.append(_Grid(scene, goal, level, tables))
            if grids[n].done:
                continue
            turned = True
            grids[n].search_next_root(t0, left)
            if grids[n].leaf is not None:
                return replace(grids[n].plan(t0), stats=_total_stats(grids, t0))
        if not turned:
            break
    plans = [g.plan(t0) for g in grids]
    return replace(
        plans[-1],
        refusal=on_grids([(g.config.displacement_step, p.refusal) for g, p in zip(grids, plans)]),
        stats=_total_stats(grids, t0),
    )


def _total_stats(grids: list[_Grid], t0: SearchClock) -> SearchStats:
    """The statistics of the grids' searches together (each grid ranks its own candidates)."""
    return SearchStats(
        expanded=sum(g.search.expanded for g in grids),
        generated=sum(g.search.generated for g in grids),
        lp_calls=sum(g.search.closure.lp_calls for g in grids),
        ik_calls=sum(g.search.reach.ik_calls for g in grids),
        time_s=t0.elapsed(),
        initial_grasps_searched=sum(g.searched for g in grids),
        initial_grasp_candidates=sum(len(g.roots) for g in grids),
    )


class _Grid:
    """The search on one contact grid (grid_levels), rooted at its candidates one at a time."""

    def __init__(self, scene: Scene, goal: GoalPose, config: SearchConfig, tables: GraspTables | None):
        self.config = config
        self.search = _Search(scene, goal, config)
        self.roots, self.refusal = _roots(scene, config, self.search, tables)
        if self.roots:
            self.search.plan_switch_bounds(self.roots.per_finger())
        self.pending = iter(self.roots)
        self.leaf: _Node | None = None
        self.searched, self.skipped = 0, 0
        self.first_skip: AtRoot | None = None
        self.last: AtRoot | None = None
        self.done = not self.roots

    def search_next_root(self, t0: SearchClock, budget: int) -> None:
        """Algorithm 1 from the next candidate that passes the precheck (those that fail it
        skipped), with at most `budget` expansions; `leaf` is the goal node when it found a plan,
        and `done` set when it did or no root is left (search.max_initial_grasps searched, the
        budget or the time spent)."""
        for root in self.pending:
            if self.searched >= self.config.max_initial_grasps or t0.over(self.config):
                break
            why = self.search.precheck(root, candidate=self.config.initial_arclengths is None)
            if why:
                self.skipped += 1
                self.first_skip = self.first_skip or AtRoot(root, why)
                continue
            self.searched += 1
            expanded0 = self.search.expanded
            self.leaf, why = self.search.run(root, t0, self.config.root_expansions, budget)
            if self.leaf is None:
                self.last = AtRoot(root, why)
            self.done = self.leaf is not None or self.search.expanded - expanded0 >= budget
            return
        self.done = True

    def plan(self, t0: SearchClock) -> ContactPlan:
        """The plan from `leaf`, or why this grid found none."""
        search, goal = self.search, self.search.goal
        stats = search.stats(t0, self.searched, len(self.roots))
        if self.leaf is None:
            if not self.roots:
                refusal = self.refusal
            elif len(self.roots) == 1 and self.first_skip is not None:  # the one root was skipped: its own refusal
                refusal = self.first_skip.refusal
            else:
                refusal = NoPlan(
                    searched=self.searched,
                    candidates=len(self.roots),
                    skipped=self.skipped,
                    first_skipped=self.first_skip,
                    last_searched=self.last,
                    mu_plan=search.mu_plan,
                    refused=tuple(search.refused.most_common(4)),
                )
            return ContactPlan(
                goal=goal.theta,
                goal_position=goal.position,
                success=False,
                refusal=refusal,
                stats=stats,
                mu_plan=search.mu_plan,
            )
        path, leaf = [], self.leaf
        while leaf is not None:
            path.append(leaf)
            leaf = leaf.parent
        return ContactPlan(
            goal=goal.theta,
            goal_position=goal.position,
            success=True,
            nodes=search.contact_nodes(path[::-1]),
            stats=stats,
            mu_plan=search.mu_plan,
        )
