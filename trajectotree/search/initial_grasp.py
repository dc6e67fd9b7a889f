"""The initial grasp, chosen for the configured object (box or convex polygon), not fixed fractions.

Why: with a friction margin (mu_plan = search.friction_safety x scene.mu) no single grasp
admits plans for every goal. Measured at mu_plan 0.49 on the 0.20 x 0.10 m box: the old
default (0.54, 0.12, 0.36, 0.48) admits every positive goal and no negative one (its stance
of fingers 1, 2, 3 needs mu 0.67, so finger 0 can never let go); (0.06, 0.18, 0.32, 0.50)
admits -3.0..+1.5 but not +2.0..+3.0; the two together cover the 12 goals tried. So the
search is rooted at several candidates, best first, until one yields a plan.

Candidates: every assignment of grid contacts (arclength multiples of
search.initial_grid_step) to the fingers such that each contact is at least
scene.corner_margin from a corner and reachable at the initial pose (closed-form IK with
the link collision test, trajectotree.search.reach), no two fingers come within
search.finger_clearance of each other there (their link boxes and fingertip spheres at the
closed-form joint angles, trajectotree.scene.finger_clearance.fingers_clear), and at least
one finger may let go (the other three are in frictional form closure at mu_plan, which
also puts the grasp itself in closure). Ranked by their worst three-finger stance among the
fingers that may let go (largest required_mu, smallest first), then by more free fingers,
then by the paper's joint-2 heuristic at the initial pose. Many stances need no friction at
all (an antipodal pair plus a third contact), hence the tie-breaks.
For the default scene: 2916 grid assignments, 2583 candidates (0.25 s to build; a GraspTables
keeps them for the next goal). The finger test is the search's: the simulation's fingers
collide like any other bodies (trajectotree.execution.simulate).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np

from trajectotree.config import SearchConfig, mu_plan
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.scene.finger_clearance import fingers_clear, pair_distances
from trajectotree.scene.plant import Scene
from trajectotree.search.grasp import required_mu_many
from trajectotree.search.reach import Reachability

RANKING_BISECTIONS = 20  # required_mu to MU_CAP / 2^20 ~ 1e-5 for ranking (ranked to 1e-4)


def stance_fingers(num_fingers: int) -> tuple[tuple[int, ...], ...]:
    """The holding fingers of each stance: all but finger i, for each finger i."""
    return tuple(tuple(j for j in range(num_fingers) if j != i) for i in range(num_fingers))


@dataclass(frozen=True)
class GraspCandidate:
    arclengths: tuple[float, ...]  # (F,) m, each finger's contact along the boundary, in [0, perimeter)
    stance_required_mu: tuple[float, ...]  # (F,) required mu of the others when finger i lets go
    worst_stance_mu: float  # the largest of those at most mu_plan (the ranking key)
    free_fingers: int  # fingers that may let go at mu_plan


@dataclass(frozen=True, eq=False)
class GraspCandidates:
    """The ranked candidates, kept as arrays: a search reads the few it roots at, and `candidates`
    makes the thousands of GraspCandidate values only when asked (their allocation alone set off a
    full garbage collection, 20-80 ms, in a fresh process)."""

    mu_plan: float
    arclengths: np.ndarray  # (K, F) m, the candidates' contacts, ranked, best first
    stance_mu: np.ndarray  # (K, F) GraspCandidate.stance_required_mu of each
    worst_stance_mu: np.ndarray  # (K,)
    free_fingers: np.ndarray  # (K,) int
    reachable: tuple[int, ...]  # grid contacts reachable per finger at the initial pose
    assignments: int  # grid assignments before the overlap and closure filters
    refusal: Refusal | None  # why there is no candidate (NO_GRID_CONTACT, NO_INITIAL_GRASP); None when there are

    @functools.cached_property
    def candidates(self) -> tuple[GraspCandidate, ...]:
        """Ranked, best first (Python floats and ints, converted one array at a time)."""
        return tuple(
            GraspCandidate(arclengths=tuple(s), stance_required_mu=tuple(m), worst_stance_mu=w, free_fingers=f)
            for s, m, w, f in zip(
                self.arclengths.tolist(),
                self.stance_mu.tolist(),
                self.worst_stance_mu.tolist(),
                self.free_fingers.tolist(),
            )
        )

    def __len__(self) -> int:
        return len(self.arclengths)

    def root(self, k: int) -> tuple[float, ...]:
        """Candidate k's contacts as the search's keys (grid values: already canonical)."""
        return tuple(self.arclengths[k].tolist())


class GraspTables:
    """Ranked initial-grasp tables kept by whoever plans many goals of one scene and wants each
    table built once (a search given none builds its own, and its search time includes it)."""

    def __init__(self):
        self._tables: dict[tuple, GraspCandidates] = {}

    def get(self, scene: Scene, search: SearchConfig, reach: Reachability | None = None) -> GraspCandidates:
        """initial_grasp_candidates for these settings, built on the first request."""
        key = (
            scene.config,
            search.friction_safety,
            search.initial_grid_step,
            search.nominal_joint2,
            search.finger_clearance,
        )
        if key not in self._tables:
            self._tables[key] = initial_grasp_candidates(scene, search, reach)
        return self._tables[key]


def initial_grasp_candidates(scene: Scene, search: SearchConfig, reach: Reachability | None = None) -> GraspCandidates:
    """The ranked candidate initial grasps for scene's object (GraspTables keeps them)."""
    return _build(scene, search, reach or Reachability(scene))


def grid_contacts(scene: Scene, step: float, reach: Reachability) -> list[np.ndarray]:
    """Per finger, the grid arclengths that are corner-free and reachable at the initial pose."""
    c = scene.config
    boundary = c.shape
    grid = np.round(np.arange(0.0, boundary.perimeter - 1e-9, step), 9)
    grid = grid[boundary.corner_free(grid, c.corner_margin)]
    out = []
    for finger in range(scene.num_fingers):
        q = reach.closed_form_many(np.asarray(c.initial_pose, dtype=float), finger, grid)
        out.append(grid[np.isfinite(q[:, 0])])
    return out


def grasp_joints(scene: Scene, reach: Reachability, grasps: np.ndarray) -> np.ndarray:
    """(M, 2F) rad, the closed-form joint angles of each grasp (M, F) at the initial pose."""
    pose = np.asarray(scene.config.initial_pose, dtype=float)
    q = np.zeros((len(grasps), 2 * scene.num_fingers))
    for i in range(scene.num_fingers):  # each finger holds a few distinct contacts: their IK once each
        contacts, index = np.unique(grasps[:, i], return_inverse=True)
        q[:, 2 * i : 2 * i + 2] = reach.closed_form_many(pose, i, contacts)[index.ravel()]
    return q


def fingers_apart(scene: Scene, reach: Reachability, grasps: np.ndarray, clearance: float) -> np.ndarray:
    """(M,) bool: no two fingers of each grasp (M, F) within `clearance` m of each other at the
    initial pose (link boxes and fingertip spheres, at the closed-form joint angles; fingers_clear).
    Each pair's distance depends on its two contacts alone: computed once per distinct pair of
    contacts (the default table: 1.1 k of them instead of 2.9 k grasps x 6 pairs)."""
    q, apart = grasp_joints(scene, reach, grasps), np.ones(len(grasps), dtype=bool)
    for i, j in itertools.combinations(range(scene.num_fingers), 2):
        contacts, first, index = np.unique(grasps[:, [i, j]], axis=0, return_index=True, return_inverse=True)
        pair_q = np.zeros((len(contacts), 2 * scene.num_fingers))
        pair_q[:, [2 * i, 2 * i + 1, 2 * j, 2 * j + 1]] = q[first][:, [2 * i, 2 * i + 1, 2 * j, 2 * j + 1]]
        d = pair_distances(scene.fingers, pair_q, reach.tip_radius, pairs=[(i, j)])[(i, j)]
        apart &= fingers_clear(d, clearance)[index.ravel()]
    return apart


def _joint2_cost(scene: Scene, search: SearchConfig, reach: Reachability, grasps: np.ndarray) -> np.ndarray:
    """sum_i |q2_i - nominal_joint2| of each grasp (M, F) at the initial pose (closed form)."""
    q2, cost = grasp_joints(scene, reach, grasps)[:, 1::2], np.zeros(len(grasps))
    for i in range(scene.num_fingers):  # finger by finger, the sum's order as before
        cost = cost + np.abs(q2[:, i] - search.nominal_joint2)
    return cost


def symmetric_key(boundary, stances: np.ndarray) -> np.ndarray:
    """(K, 3) a key per set of contacts (K, 3) (arclengths), equal for sets whose frictional form
    closure is the same at every mu: their sorted arclengths and, on the box, the least of those
    of its four images under the box's symmetries (the half turn s + P/2 and the mirror in its y
    axis 2 h + w - s, the mirror in x being their product), which map contacts, normals and cone
    edges onto one another and the wrench space linearly onto itself."""
    if not boundary.is_box:
        return np.sort(stances, axis=1)
    per, (a, b) = boundary.perimeter, boundary.box_half
    mirror = 4 * b + 2 * a  # 2 h + w
    images = [stances, stances + per / 2, mirror - stances, mirror - stances + per / 2]

    def wrapped(x):  # arclength keys in [0, perimeter) to 1e-9 m, as the search's
        key = np.round(np.mod(x, per), 9)
        return np.where(key >= round(per, 9), 0.0, key)

    keys = np.stack([np.sort(wrapped(x), axis=1) for x in images])  # (4, K, 3)
    best = np.lexsort(keys.transpose(2, 0, 1)[::-1], axis=0)[0]  # the least image of each row
    return keys[best, np.arange(len(stances))]


def _build(scene: Scene, search: SearchConfig, reach: Reachability) -> GraspCandidates:
    mu = mu_plan(scene.config, search)
    num_fingers = scene.num_fingers
    stances_of = stance_fingers(num_fingers)
    per_finger = grid_contacts(scene, search.initial_grid_step, reach)
    counts = tuple(len(s) for s in per_finger)
    grasps = np.array(list(itertools.product(*per_finger))).reshape(-1, num_fingers)
    assignments = len(grasps)
    if assignments == 0:
        missing = [i for i, n in enumerate(counts) if n == 0]
        none = np.zeros((0, num_fingers))
        return GraspCandidates(
            mu,
            none,
            none,
            np.zeros(0),
            np.zeros(0, dtype=int),
            counts,
            0,
            Refusal(RefusalKind.NO_GRID_CONTACT, fingers=tuple(missing)),
        )
    p, n = reach.contacts(grasps.ravel())
    p, n = p.reshape(-1, num_fingers, 2), n.reshape(-1, num_fingers, 2)
    tips = p + reach.tip_radius * n
    apart = np.ones(len(grasps), dtype=bool)
    for i, j in itertools.combinations(range(num_fingers), 2):
        apart &= np.linalg.norm(tips[:, i] - tips[:, j], axis=1) >= 2 * reach.tip_radius
    apart[apart] = fingers_apart(scene, reach, grasps[apart], search.finger_clearance)
    grasps, p, n = grasps[apart], p[apart], n[apart]
    # one required_mu per distinct set of F - 1 contacts, whichever fingers hold them (closure
    # does not depend on their order) and, on the box, up to its symmetries, in one vectorized bisection
    stances = np.concatenate([grasps[:, others] for others in stances_of])  # (F M, F - 1), finger i's first
    _, first, index = np.unique(
        symmetric_key(scene.config.shape, stances), axis=0, return_index=True, return_inverse=True
    )
    grasp_of, stance_of = first % len(grasps), first // len(grasps)
    pick = np.array(stances_of)[stance_of]  # (U, F - 1) the fingers of each distinct stance's first holder
    mus = required_mu_many(p[grasp_of[:, None], pick], n[grasp_of[:, None], pick], bisections=RANKING_BISECTIONS)
    stance_mu = mus[index.ravel()].reshape(num_fingers, len(grasps)).T
    free = stance_mu < mu
    worst = np.where(free, stance_mu, -np.inf).max(axis=1)
    keep = np.flatnonzero(free.any(axis=1))
    # ties (many stances need ~0: an antipodal pair plus one) go to more free fingers, then to
    # the paper's heuristic at the initial pose (second joints near search.nominal_joint2)
    order = keep[
        np.lexsort(
            (_joint2_cost(scene, search, reach, grasps[keep]), -free[keep].sum(axis=1), np.round(worst[keep], 4))
        )
    ]
    refusal = (
        None
        if len(order)
        else Refusal(
            RefusalKind.NO_INITIAL_GRASP,
            mu_plan=mu,
            required_mu=float(np.min(stance_mu)) if stance_mu.size else np.inf,
            count=assignments,
            subset=int(apart.sum()),
        )
    )
    return GraspCandidates(
        mu, grasps[order], stance_mu[order], worst[order], free[order].sum(axis=1), counts, assignments, refusal
    )
