"""Per finger, every contact it can ever hold along the search's object path, and the fewest
contact switches it alone needs from each to the last node (trajectotree.search.tree; not in the
paper, and it changes no plan).

Before the search, one vectorized closed-form pass per finger tabulates every contact the finger
can ever hold (its initial arclengths plus sums of displacements) at every depth: corner-free and
reachable or not, and q2 for the heuristic. From that table, the fewest switches per finger to the
last node: only one finger switches per step, so a node whose fingers together need more switches
than steps remain is a dead end and is not inserted. Without this bound the DFS spends seconds in
subtrees that cannot reach the goal (this hand reaches only ~0.15-0.2 m of the boundary from each
base, so large rotations need most of the nine steps).
"""

from __future__ import annotations

import numpy as np

from trajectotree.config import SearchConfig
from trajectotree.scene.plant import Scene
from trajectotree.search.reach import Reachability
from trajectotree.search.stance import arclength_key


class SwitchBound:
    """The per-finger table of one search (one object path and contact grid)."""

    def __init__(self, scene: Scene, reach: Reachability, poses: np.ndarray, config: SearchConfig):
        self.scene, self.reach, self.poses, self.config = scene, reach, poses, config
        self.boundary = scene.config.shape
        half = (config.num_displacements - 1) // 2
        self.displacements = config.displacement_step * np.arange(-half, half + 1)
        self.min_switches: list[list[dict[float, float]]] = []  # [finger][depth][arclength] -> switches
        # [finger][depth][arclength] -> the first later node at which that contact is out of reach (inf: none)
        self.lost: list[list[dict[float, float]]] = []
        self.joint2: list[list[dict[float, float]]] = []  # [finger][depth][arclength] -> q2 (reachable only)
        # [finger][depth][arclength] -> (q1, q2), the closed form's joint angles where joint2 has q2
        # (and at depth 0 for the roots' contacts)
        self.joints: list[list[dict[float, tuple[float, float]]]] = []
        self._moves: dict[float, list[float]] = {}

    def wrap(self, s: float) -> float:
        return arclength_key(self.boundary.perimeter, s)

    def plan(self, starts) -> None:
        """Per finger, over the arclengths it can ever hold (its initial contacts, one per
        candidate root, plus sums of displacements), which are corner-free and reachable
        (closed form, vectorized) at each depth, with their joint-2 angle for the heuristic;
        then the fewest contact switches that keep that finger alone on such contacts from
        each (depth, arclength) to the last node. A node whose fingers together need more
        switches than steps remain has no completion (one switch per step), so pruning it
        never removes a plan; it only spares the DFS hopeless subtrees."""
        last = self.config.num_nodes - 1
        for finger, s0s in enumerate(starts):
            grid, frontier = set(s0s), set(s0s)  # every arclength the finger can ever hold
            for _ in range(last):
                frontier = {m for s in frontier for m in self.moves(s)} - grid
                grid |= frontier
            grid = np.array(sorted(grid))
            corner_free = self.boundary.corner_free(grid, self.scene.config.corner_margin)
            # reachability of the whole grid at every depth in one vectorized call
            q = self.reach.closed_form_many(np.repeat(self.poses[1:], len(grid), axis=0), finger, np.tile(grid, last))
            q = q.reshape(last, len(grid), 2)
            allowed = [
                {s: (a, b) for s, (a, b) in zip(grid[ok].tolist(), row[ok].tolist())}
                for row in q
                for ok in [corner_free & np.isfinite(row[:, 1])]
            ]
            starts = sorted(s0s)
            at_start = self.reach.closed_form_many(self.poses[0], finger, starts).tolist()
            angles = [dict(zip(starts, map(tuple, at_start)))]  # node 0: the roots' contacts (nan: out of reach)
            for depth in range(1, last + 1):  # forward: contacts reachable from s0 by displacements
                candidates = {m for s in angles[-1] for m in self.moves(s)}
                angles.append({s: allowed[depth - 1][s] for s in candidates if s in allowed[depth - 1]})
            layers = [dict.fromkeys(s0s, np.nan)] + [{s: q[1] for s, q in layer.items()} for layer in angles[1:]]
            cost = [dict.fromkeys(layers[last], 0)]
            for depth in range(last - 1, -1, -1):  # backward: fewest switches to the end
                after, here = cost[0], {}
                for s in layers[depth]:
                    here[s] = min(after.get(s, np.inf), 1 + min(after.get(m, np.inf) for m in self.moves(s)))
                cost.insert(0, here)
            lost = [dict.fromkeys(layers[last], np.inf)]  # backward: the first later node without the contact
            for depth in range(last - 1, -1, -1):
                later, there = lost[0], layers[depth + 1]
                lost.insert(0, {s: later[s] if s in there else depth + 1 for s in layers[depth]})
            self.joint2.append(layers)
            self.joints.append(angles)
            self.min_switches.append(cost)
            self.lost.append(lost)

    def moves(self, s: float) -> list[float]:
        """The arclengths s + d for every d in D_cp (wrapped keys), memoized."""
        if s not in self._moves:
            self._moves[s] = [self.wrap(s + d) for d in self.displacements]
        return self._moves[s]

    def tabulated(self, depth: int, finger: int, s: float) -> np.ndarray | None:
        """(2,) rad, `finger`'s closed-form joint angles with its contact at arclength s at node
        `depth` from the table (plan); None when it has none there (not tabulated, or out of reach)."""
        q = self.joints[finger][depth].get(s) if self.joints else None
        return None if q is None or q[0] != q[0] else np.array(q)  # q[0] != q[0]: nan

    def angles(self, depth: int, finger: int, s: float) -> np.ndarray:
        """The same, else Reachability.closed_form's (nan when out of reach)."""
        q = self.tabulated(depth, finger, s)
        return self.reach.closed_form(self.poses[depth], finger, s).q if q is None else q

    def deadlines_met(self, depth: int, arclengths) -> bool:
        """Whether the fingers can switch in time: each must have moved by the first node at which
        its contact at `depth` is out of reach, one switch per node, so the k-th earliest of those
        nodes must be depth + k or later (precheck's test at the root, here at any node)."""
        deadlines = sorted(self.lost[i][depth].get(s, depth) for i, s in enumerate(arclengths))
        return all(d >= depth + k for k, d in enumerate(deadlines, start=1))

    def switches_needed(self, depth: int, arclengths) -> float:
        return sum(self.min_switches[i][depth].get(s, np.inf) for i, s in enumerate(arclengths))
