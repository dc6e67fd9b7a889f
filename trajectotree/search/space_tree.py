"""The contact-sequence planner in space: the paper's Algorithm 1 (Sec. III-A) for a hand in space (scene.spatial).

The same depth-first search over finger-to-contact assignments along a fixed object path as in the plane
(trajectotree.search.tree), one finger switching per node while the other three hold.
The path is the geodesic (slerp) from the start orientation to the goal, the object's position kept.

Stance checks (trajectotree.search.stance; not in the paper): the stances (and the roots' four fingers) must hold the
object at their planned and rolled contacts with every joint within search.space_torque_fraction of its
motor's limit and, with search.space_stance_margin require, with friction cones at
search.space_stance_friction_safety x scene.mu (at most mu_plan): headroom for the closed loop in a heavier or more
slippery world than the plan assumed. With prefer, a stance that holds only at mu_plan is kept but ordered after
those at the margin and those at search.space_stance_fallback_safety x scene.mu, and the search first looks for a
plan of margin stances alone, then of those and the fallback's, each within search.space_margin_first_share of the
budgets left (_SpaceSearch.passes).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from trajectotree.config import SearchConfig
from trajectotree.contact_plan import SearchStats, SpaceContactNode, SpaceContactPlan
from trajectotree.geometry import BOX_FACE_NAMES, box_face_grid, quaternion_angle, quaternion_slerp
from trajectotree.refusal import AtRoot, NoPlan, Refusal, RefusalKind
from trajectotree.scene.spatial import START_POSE
from trajectotree.scene.statics import edge_wrenches_W
from trajectotree.search.grasp import SpatialClosure
from trajectotree.search.spatial_reach import SpatialReach, box_transform
from trajectotree.search.spatial_rolling import (
    chain,
    chain_jacobian,
    lifted_swing,
    moved_joints,
    on_face,
    rolled_step,
)
from trajectotree.search.stance import (
    SpatialHoldingLp,
    SpatialPushLp,
    spatial_push_capacity,
    spatial_torque_rows,
)
from trajectotree.search.tree import SearchClock

# rad, the largest rotation between two nodes. One finger switches per node, so the segments bound the
# switches: of the 30 seed-0 goals of scripts/search_space.py, 30 deg planned 23 (turns over 120 deg need
# more switches than 4-6 segments give), 20 deg 28 (docs/measurements.md), and 15 deg, on the 7 that 30 deg
# missed, planned 5 as 20 deg did, in more time per goal (each node costs reach and stance checks); measured
# before every face was a move's candidate, with which 20 deg plans all 30 and the 23 axis-aligned goals. A held
# contact (at most the 6.5 cm cube's half-diagonal, 5.6 cm, from the centre) moves at most 2 cm between nodes,
# where reach and clearance are checked; a 180 deg goal takes 9 segments.
SPACE_MAX_SEGMENT_ROTATION = math.radians(20.0)
SPACE_GRID_PER_SIDE = 3  # contacts per face: 3 x 3, a fingertip radius in from the edges
PYRAMID_EDGES = 8  # each friction cone linearized by an inscribed 8-edge pyramid
SPACE_ROOT_CHOICES = 4  # contacts per finger ranked (facing the finger first) for the initial grasps
SPACE_MAX_ROOTS = 12  # initial grasps searched at most


def space_object_path(
    goal_quaternion, start=START_POSE, max_rotation: float = SPACE_MAX_SEGMENT_ROTATION
) -> np.ndarray:
    """(N, 7) poses [qw, qx, qy, qz, px, py, pz] on the geodesic from `start` to the goal orientation at
    the start's position; N - 1 = the angle over max_rotation, rounded up (1 at least)."""
    start = np.asarray(start, dtype=float)
    goal = np.asarray(goal_quaternion, dtype=float)
    segments = max(1, math.ceil(quaternion_angle(start[:4], goal) / max_rotation - 1e-9))
    quats = quaternion_slerp(start[:4], goal, np.linspace(0.0, 1.0, segments + 1))
    return np.hstack([quats, np.tile(start[4:], (segments + 1, 1))])


@dataclass(frozen=True)
class SpaceRoot:
    """A measured grasp the search in space roots at (planning.start.space_start_root checks it): the cube's pose,
    the joint angles and each finger's contact, in closure at mu_plan."""

    pose: np.ndarray  # (7,) [qw, qx, qy, qz, px, py, pz] in W
    q: np.ndarray  # (F, n) rad
    p_BC: np.ndarray  # (F, 3) m, each finger's contact on its face, in B
    faces: tuple[int, ...]  # each contact's face (geometry.BOX_FACE_NORMALS order)


@dataclass(frozen=True)
class _SpaceNode:
    depth: int
    contacts: tuple[int, ...]  # per finger, its contact's index in the grid (face * per face + cell)
    q: np.ndarray  # (F, n) rad
    switching_finger: int | None
    parent: _SpaceNode | None
    stance_torque: float | None = None  # N m
    push: float | None = None  # N
    rolled: np.ndarray | None = None  # (F, 3) m in B, each fingertip rolled off its contact since it landed
    # the least of hold_frictions at which its stance holds the cube within the motors (nan: at none); mu_hold: at
    # the margin's friction
    stance_mu: float = float("nan")


@dataclass(frozen=True)
class _SpaceChild:
    """A child proposed by GetNeighbors, checked when popped (IsFeasible)."""

    parent: _SpaceNode
    contacts: tuple[int, ...]
    finger: int | None
    q_held: dict  # {finger: (n,)} the holding fingers' angles at the child's pose
    stance_torque: float
    push: float
    rolled: np.ndarray  # (F, 3) m in B, the child's rolled offsets (_SpaceSearch.rolled_stance)
    stance_mu: float  # the least of hold_frictions at which its stance holds the cube within the motors


class _SpaceSearch:
    """One run of Algorithm 1 in space; holds the reach, closure and holding caches and the counters."""

    def __init__(self, scene, goal_quaternion, config: SearchConfig, mu: float, root: SpaceRoot | None = None):
        self.scene, self.mu, self.root = scene, mu, root
        self.config = replace(config, time_budget_s=config.space_time_budget_s)  # the budget in space
        self.poses = space_object_path(goal_quaternion, START_POSE if root is None else root.pose)
        p_BC, n_B = box_face_grid(scene.object.half, SPACE_GRID_PER_SIDE, scene.tip_radius)
        per_face = p_BC.shape[1]
        self.p_BC = p_BC.reshape(-1, 3)
        self.n_B = np.repeat(n_B, per_face, axis=0)
        self.face = np.repeat(np.arange(len(n_B)), per_face)
        if root is not None:  # the measured contacts join the candidates, after the grid's
            self.p_BC = np.vstack([self.p_BC, root.p_BC])
            self.n_B = np.vstack([self.n_B, n_B[list(root.faces)]])
            self.face = np.concatenate([self.face, root.faces])
        self.p_BF = self.p_BC + scene.tip_radius * self.n_B
        self.reach = SpatialReach(scene)
        self.closure = SpatialClosure(mu, half_size=float(max(scene.object.half)), num_edges=PYRAMID_EDGES)
        n = len(scene.fingers[0].q_lower)
        self.hold_lps = {k: SpatialHoldingLp(k, PYRAMID_EDGES, n) for k in (3, 4)}
        self.push_lps = {k: SpatialPushLp(k, PYRAMID_EDGES, n, config.push_normal_force) for k in (3, 4)}
        self.w_hold = np.r_[0.0, 0.0, scene.object.mass * scene.gravity, 0.0, 0.0, 0.0]
        # N m, the torque a stance may use: search.space_torque_fraction of the weakest motor, the rest left to the
        # closed loop for a heavier cube than planned
        self.tau_limit = config.space_torque_fraction * float(np.min(scene.tau_max))
        # the stance margin's friction (search.space_stance_friction_safety x the world's, at most mu_plan): a stance
        # that holds at it holds where the world has that much less friction than planned
        margin = config.space_stance_margin != "none"
        self.mu_hold = min(mu, config.space_stance_friction_safety * scene.object.mu) if margin else mu
        # the frictions a stance is tried at, lowest first: the margin's, then (prefer) the fallback's
        # (search.space_stance_fallback_safety, where it lies between) and mu_plan's; a stance's rank is the index of
        # the first at which it holds
        prefer = config.space_stance_margin == "prefer" and self.mu_hold < mu
        fallback = min(mu, config.space_stance_fallback_safety * scene.object.mu)
        levels = {f for f in (self.mu_hold, fallback, mu) if f >= self.mu_hold}
        self.hold_frictions = tuple(sorted(levels)) if prefer else (self.mu_hold,)
        self._reach: dict[tuple, object] = {}
        self._closure: dict[tuple, object] = {}
        self.refused: Counter[Refusal] = Counter()
        self.visited: set[tuple] = set()
        self.expanded = self.generated = 0

    @property
    def lp_calls(self) -> int:
        lps = [*self.closure.lps.values(), *self.hold_lps.values(), *self.push_lps.values()]
        return sum(lp.lp_calls for lp in lps)

    # -- cached checks --------------------------------------------------------------------------
    def finger_reach(self, depth: int, finger: int, contact: int, seed=None):
        key = (depth, finger, contact)
        if key not in self._reach:
            self._reach[key] = self.reach.solve(self.poses[depth], finger, self.p_BF[contact], seed)
        return self._reach[key]

    def closed(self, contacts) -> object:
        """The 6-D closure at mu_plan of `contacts` (grid indices): the same at every pose (the box frame's)."""
        key = tuple(sorted(contacts))
        if key not in self._closure:
            self._closure[key] = self.closure.check(self.p_BC[list(key)], self.n_B[list(key)])
        return self._closure[key]

    def facing(self, depth: int, finger: int) -> np.ndarray:
        """(K,) how squarely each contact's face turns to the finger's base at pose `depth`: the cosine
        between the face's normal and the direction to the base (links reaching round the box meet it)."""
        R = box_transform(self.poses[depth]).rotation().matrix()
        to_base = self.scene.fingers[finger].p_W_joint[0] - self.p_BC @ R.T - self.poses[depth][4:]
        return np.einsum("kc,kc->k", self.n_B @ R.T, to_base / np.linalg.norm(to_base, axis=1, keepdims=True))

    def holding(self, depth: int, contacts, fingers, q_rows, mu: float) -> tuple[float, float]:
        """(N m, N): the least largest joint torque with which `fingers` on `contacts` at angles q_rows
        hold the box at rest at pose `depth` (their own weight included), and the hardest push along
        +-x, +-y, +-z in W they resist within their motors, both with friction cones at `mu`."""
        return self.holding_at(depth, self.p_BC[list(contacts)], self.n_B[list(contacts)], fingers, q_rows, mu)

    def holding_at(self, depth: int, p_BC, n_B, fingers, q_rows, mu: float, J=None) -> tuple[float, float]:
        """holding's (N m, N) for `fingers` on the points p_BC (k, 3) m in B of the faces of outward normals n_B;
        J (k, 3, n): the contact points' Jacobians where the caller has them."""
        R = box_transform(self.poses[depth]).rotation().matrix()
        p_WC, n_W = p_BC @ R.T, n_B @ R.T
        q = np.zeros((self.scene.num_fingers, len(self.scene.fingers[0].q_lower)))
        for i, row in zip(fingers, q_rows):
            q[i] = row
        if J is None:
            J = np.array(
                [self.scene.fingers[i].jacobian(q[i], -self.scene.tip_radius * n) for i, n in zip(fingers, n_W)]
            )
        W = edge_wrenches_W(p_WC, n_W, mu, PYRAMID_EDGES)
        A = spatial_torque_rows(J, n_W, mu, PYRAMID_EDGES)
        tau_g = self.scene.gravity_torques(q)[list(fingers)]
        k = len(fingers)
        torque, _ = self.hold_lps[k].solve(W, A, tau_g, self.w_hold)
        if torque > self.tau_limit:
            return torque, -np.inf
        push = spatial_push_capacity(self.push_lps[k], W, A, tau_g, self.scene.tau_max[list(fingers)], self.w_hold)
        return torque, push

    # -- IsFeasible -----------------------------------------------------------------------------
    def feasible(self, child: _SpaceChild) -> tuple[_SpaceNode | None, Refusal | None]:
        """The child as a node (its joint angles), or why it is a dead end: its four contacts not in
        closure at mu_plan, the moving finger's new contact out of reach, or the hand's links not clear."""
        depth = child.parent.depth + 1
        closure = self.closed(child.contacts)
        if not closure.in_closure:
            return None, Refusal(RefusalKind.NOT_IN_CLOSURE, mu_plan=self.mu, margin=closure.margin)
        q = np.array([child.q_held.get(i) if i in child.q_held else None for i in range(len(child.contacts))], object)
        if child.finger is not None:
            reach = self.finger_reach(depth, child.finger, child.contacts[child.finger], child.parent.q[child.finger])
            if not reach.reachable:
                return None, Refusal(RefusalKind.UNREACHABLE, fingers=(child.finger,), cause=reach.refusal)
            q[child.finger] = reach.q
        q = np.array(q.tolist(), dtype=float)
        clash = self.reach.links_clear(self.poses[depth], q) or self.swing_clash(child, q)
        if clash:
            return None, clash
        node = _SpaceNode(
            depth,
            child.contacts,
            q,
            child.finger,
            child.parent,
            child.stance_torque,
            child.push,
            child.rolled,
            child.stance_mu,
        )
        return node, None

    def swing_clash(self, child: _SpaceChild, q_child) -> Refusal | None:
        """Why the moving finger's swing to `child` (joint angles q_child (F, n) at its pose) is refused (None when it
        is not, or no finger moves): at a few points of its lifted path (spatial_rolling.lifted_swing, the cube on
        the geodesic between the two poses) it comes within search.finger_clearance of another finger, the holders
        where their fingertips have rolled to (the fingertip spheres of seed-0 goal 25's planned swing struck, executed,
        where a holder had rolled 16 mm toward the swing's path). With search.rolled_stances false: no check."""
        i, parent = child.finger, child.parent
        if i is None or not self.config.rolled_stances:
            return None
        d0 = parent.depth
        a_B = self.p_BF[parent.contacts[i]] + parent.rolled[i]
        s, p_B = lifted_swing(a_B, self.p_BF[child.contacts[i]], self.scene.object.half, self.scene.tip_radius)
        quats = quaternion_slerp(self.poses[d0][:4], self.poses[d0 + 1][:4], s)
        poses = np.hstack([quats, (1.0 - s)[:, None] * self.poses[d0][4:] + s[:, None] * self.poses[d0 + 1][4:]])
        R = np.array([box_transform(pose).rotation().matrix() for pose in poses])  # (S, 3, 3)
        u = s[:, None, None]
        targets_B = self.p_BF[list(parent.contacts)] + (1.0 - u) * parent.rolled + u * child.rolled  # (S, F, 3)
        targets_B[:, i] = p_B
        targets_W = poses[:, None, 4:] + np.einsum("sij,sfj->sfi", R, targets_B)
        q_start = (1.0 - u) * parent.q + u * q_child  # (S, F, n)
        q_all = np.stack(
            [moved_joints(f, q_start[:, j], targets_W[:, j]) for j, f in enumerate(self.scene.fingers)], axis=1
        )
        for pose, q in zip(poses, q_all):
            clash = self.reach.links_clear(pose, q)
            if clash is not None and clash.kind == RefusalKind.FINGERS_COLLIDE and i in clash.fingers:
                return replace(clash, count=1)
        return None

    # -- GetNeighbors ---------------------------------------------------------------------------
    def neighbors(self, node: _SpaceNode) -> list[_SpaceChild]:
        """The children of `node`, best first: those whose stance holds at the margin's friction (prefer), then no
        switch, then each free finger's moves (the finger rolled
        furthest since it landed first, then its stance's push capacity, larger first), each finger's new contacts
        on faces turned to its base before those turned away, then freeing more fingers (freedom), then facing it
        more squarely, first. A stance holds the cube within the motors at its planned contacts and at those its
        fingertips roll to (rolled_stance)."""
        depth = node.depth + 1
        held = {i: self.finger_reach(depth, i, c, node.q[i]) for i, c in enumerate(node.contacts)}
        stuck = [i for i, r in held.items() if not r.reachable]
        if len(stuck) > 1:
            self.refused[Refusal(RefusalKind.CONTACTS_LOST, fingers=tuple(stuck))] += 1
            return []
        options = stuck or [None, *range(self.scene.num_fingers)]
        ranked = []
        for finger in options:
            stance = tuple(i for i in range(self.scene.num_fingers) if i != finger)
            contacts = [node.contacts[i] for i in stance]
            if finger is not None and not self.closed(contacts).in_closure:
                self.refused[Refusal(RefusalKind.FINGER_HELD, fingers=(finger,), stance=stance, mu_plan=self.mu)] += 1
                continue
            held_stance, why = self.stance(node, depth, stance, held)
            if why is not None:
                self.refused[why] += 1
                continue
            torque, push, rolled, rank = held_stance
            # the finger rolled furthest since it landed moves first (it lands back on a grid point, its roll reset):
            # by push capacity alone axes 18 and 19 found no plan in the 30 s budget (1296, 1761 expansions), so
            # ordered in 544 and 102 (all rolls are 0 with search.rolled_stances off: the push's order); a stance
            # within the margin before one at the fallback's friction, before one that holds only at mu_plan
            # (search.space_stance_margin prefer)
            rolled_far = 0.0 if finger is None else -float(np.linalg.norm(node.rolled[finger]))  # m
            ranked.append((rank, finger is not None, rolled_far, -push, finger, stance, torque, push, rolled))
        out = []
        for rank, _, _, _, finger, stance, torque, push, rolled in sorted(ranked, key=lambda r: r[:4]):
            q_held, stance_mu = {i: held[i].q for i in stance}, self.hold_frictions[rank]
            if finger is None:
                out.append(_SpaceChild(node, node.contacts, None, q_held, torque, push, rolled, stance_mu))
                continue
            others = self.p_BF[[node.contacts[i] for i in stance]] + rolled[list(stance)]  # where they rolled to
            facing, moves = self.facing(depth, finger), []
            for c in range(len(self.p_BC)):
                if c == node.contacts[finger]:
                    continue
                if np.min(np.linalg.norm(others - self.p_BF[c], axis=1)) < 2 * self.scene.tip_radius:
                    continue  # the fingertip spheres would overlap
                contacts = list(node.contacts)
                contacts[finger] = int(c)
                # a face turned away from the finger's base is no dead end: the bottom face and faces tilted
                # down are reached from under (IsFeasible's reach decides), so they come after those turned to it
                moves.append((bool(facing[c] <= 0.0), -self.freedom(contacts), -facing[c], tuple(contacts)))
            for *_, contacts in sorted(moves):
                out.append(_SpaceChild(node, contacts, finger, q_held, torque, push, rolled, stance_mu))
        return out

    def stance(self, node: _SpaceNode, depth: int, stance, held) -> tuple[tuple | None, Refusal | None]:
        """((largest joint torque N m, push capacity N, the child's rolled offsets (F, 3) m in B, its rank: the index
        in hold_frictions of the friction it holds at), None) for `stance` holding the cube from `node` to the child at
        `depth` at angles
        held[i].q: within the motors at its planned contacts at both ends and at those its fingertips roll to
        (rolled_stance), at the first of hold_frictions at which it does; or (None, why it holds at none)."""
        contacts = [node.contacts[i] for i in stance]
        for mu in self.hold_frictions:
            torque0, _ = self.holding(node.depth, contacts, stance, node.q[list(stance)], mu)
            if torque0 > self.tau_limit:
                why = Refusal(RefusalKind.STANCE_OVER_MOTORS, stance=stance, limit=self.tau_limit)
                continue
            rolled, rolled_torque, why = self.rolled_stance(node, depth, stance, held, mu)  # before the push's LPs
            if why is not None:
                if why.kind != RefusalKind.STANCE_OVER_MOTORS:
                    return None, why  # off its faces or open: the same at any friction
                continue
            torque1, push = self.holding(depth, contacts, stance, [held[i].q for i in stance], mu)
            if torque1 > self.tau_limit:
                why = Refusal(RefusalKind.STANCE_OVER_MOTORS, stance=stance, limit=self.tau_limit)
                continue
            return (max(torque0, torque1, rolled_torque), push, rolled, self.hold_frictions.index(mu)), None
        return None, why

    def rolled_stance(
        self, node: _SpaceNode, depth: int, stance, held, mu: float
    ) -> tuple[np.ndarray, float, Refusal | None]:
        """(the child's rolled offsets (F, 3) m in B, the largest joint torque (N m) with which `stance` holds the cube
        at its rolled contacts, why it cannot (None when it can)) for the transition from `node` to the child at
        `depth` in which `stance` holds at angles held[i].q (spatial_rolling): at both ends each rolled contact on its
        face and search.rolled_corner_gap short of its edges (a sphere that rolls onto an edge pivots over it), the
        stance in closure at mu_plan and held within the motors there with friction cones at `mu`. The finger that
        moves lands on its planned point (offset 0). With search.rolled_stances false: no offsets, no checks."""
        offsets = np.zeros_like(node.rolled)
        if not self.config.rolled_stances:
            return offsets, 0.0, None
        R0, R1 = (box_transform(self.poses[d]).rotation().matrix() for d in (node.depth, depth))
        fingers, r = self.scene.fingers, self.scene.tip_radius
        for i in stance:
            step = rolled_step(fingers[i], node.q[i], held[i].q, R0, R1, self.n_B[node.contacts[i]], r)
            offsets[i] = node.rolled[i] + step
        contacts, gap = [node.contacts[i] for i in stance], self.config.rolled_corner_gap
        ends = (node.depth, depth)
        p_BC = np.stack([self.p_BC[contacts] + rolled[list(stance)] for rolled in (node.rolled, offsets)])  # (2, k, 3)
        n_B = self.n_B[contacts]
        for p in p_BC:
            if not np.all(on_face(p, n_B, self.scene.object.half, gap)):
                return offsets, np.inf, Refusal(RefusalKind.STANCE_ROLLS_OFF, stance=stance, limit=gap)
            if not self.closure.check(p, n_B).in_closure:
                return offsets, np.inf, Refusal(RefusalKind.STANCE_ROLLED_OPEN, stance=stance, mu_plan=self.mu)
        poses = self.poses[list(ends)]
        R = np.array([box_transform(pose).rotation().matrix() for pose in poses])
        p_WF = poses[:, None, 4:] + np.einsum("eij,ekj->eki", R, p_BC + r * n_B)  # (2, k, 3) the rolled tip centres
        q_rolled = [moved_joints(fingers[i], [node.q[i], held[i].q], p_WF[:, k]) for k, i in enumerate(stance)]
        p_WC = poses[:, None, 4:] + np.einsum("eij,ekj->eki", R, p_BC)
        J = np.stack(  # (2, k, 3, n) at the rolled contact points
            [chain_jacobian(*chain(fingers[i], q)[:2], p_WC[:, k]) for k, (i, q) in enumerate(zip(stance, q_rolled))],
            axis=1,
        )
        q_rolled = np.stack(q_rolled, axis=1)
        torque = max(
            self.holding_at(d, p, n_B, stance, q, mu, J[e])[0] for e, (d, p, q) in enumerate(zip(ends, p_BC, q_rolled))
        )
        if torque > self.tau_limit:
            return offsets, torque, Refusal(RefusalKind.STANCE_OVER_MOTORS, stance=stance, limit=self.tau_limit)
        return offsets, torque, None

    def freedom(self, contacts) -> int:
        """How many fingers of a grasp on `contacts` may let go (the other three in closure at mu_plan):
        how many ways on a node leaves the search (a grasp that frees none is a dead end after its node)."""
        return sum(self.closed(contacts[:i] + contacts[i + 1 :]).in_closure for i in range(len(contacts)))

    # -- Algorithm 1 ----------------------------------------------------------------------------
    def roots(self) -> list[_SpaceNode]:
        """Initial grasps at the start pose, best first: each finger's SPACE_ROOT_CHOICES reachable contacts
        facing it most squarely, combined; distinct contacts in closure at mu_plan that free a finger at least,
        links clear, held by the four within the motors (at the first of hold_frictions at which they are); those held
        at the margin's friction, then those that free more fingers, then resist harder pushes, first. With a measured
        `root`, that grasp alone, whatever it frees and holds (the tree decides)."""
        fingers = tuple(range(self.scene.num_fingers))
        if self.root is not None:
            contacts = tuple(range(len(self.p_BC) - self.scene.num_fingers, len(self.p_BC)))
            q = np.asarray(self.root.q, dtype=float)
            torque, push = self.holding(0, contacts, fingers, q, self.mu_hold)
            rolled = np.zeros((len(contacts), 3))
            stance_mu = self.mu_hold if torque <= self.tau_limit else float("nan")
            return [_SpaceNode(0, contacts, q, None, None, torque, push, rolled, stance_mu)]
        choices = []
        for i in range(self.scene.num_fingers):
            mine = []
            for c in np.argsort(-self.facing(0, i), kind="stable"):
                if self.finger_reach(0, i, int(c)).reachable:
                    mine.append(int(c))
                if len(mine) == SPACE_ROOT_CHOICES:
                    break
            choices.append(mine)
        out = []
        for contacts in itertools.product(*choices):
            if len(set(contacts)) < len(contacts) or not self.closed(contacts).in_closure:
                continue
            freedom = self.freedom(list(contacts))
            if not freedom:
                continue
            q = np.array([self.finger_reach(0, i, c).q for i, c in enumerate(contacts)])
            if self.reach.links_clear(self.poses[0], q):
                continue
            for rank, mu in enumerate(self.hold_frictions):
                torque, push = self.holding(0, contacts, fingers, q, mu)
                if torque <= self.tau_limit:
                    rolled = np.zeros((len(contacts), 3))
                    node = _SpaceNode(0, contacts, q, None, None, torque, push, rolled, mu)
                    out.append(((rank, -freedom, -push), node))
                    break
            if len(out) == SPACE_MAX_ROOTS:
                break
        return [node for _, node in sorted(out, key=lambda r: r[0])]

    def passes(self) -> tuple[tuple[tuple[float, ...], SearchConfig], ...]:
        """The search's passes, each (the frictions its stances are tried at, its budgets: max_expansions and
        time_budget_s, here search.space_time_budget_s, counted from the search's start): with
        search.space_stance_margin prefer, margin stances alone (as require), then those at the fallback's friction
        after them, each pass within search.space_margin_first_share of the budgets the passes before it left (0.5 and
        0.75 of them at 0.5),
        then those that hold only at mu_plan after them within the rest (a goal whose margin plan lies under another
        root than the first gets it: the quarter turn about x has 6 of 6 stances at the margin from its second root,
        2 of 6 from its first); one pass otherwise."""
        share, frictions = self.config.space_margin_first_share, self.hold_frictions
        if len(frictions) == 1 or share == 0.0:
            return ((frictions, self.config),)
        out = []
        for k in range(1, len(frictions)):
            spent = 1.0 - (1.0 - share) ** k  # the budgets' share spent by the end of this pass
            expansions = max(1, math.floor(spent * self.config.max_expansions))
            budgets = replace(self.config, time_budget_s=spent * self.config.time_budget_s, max_expansions=expansions)
            out.append((frictions[:k], budgets))
        return (*out, (frictions, self.config))

    def begin_pass(self, frictions: tuple[float, ...]) -> None:
        """A new pass whose stances are tried at `frictions`: the states seen before are seen afresh (a state dead
        with margin stances alone may live with the others)."""
        self.hold_frictions, self.visited = frictions, set()

    def run(self, root: _SpaceNode, t0: SearchClock, budgets: SearchConfig) -> tuple[_SpaceNode | None, Refusal | None]:
        """Depth-first search from `root` to the last node, within budgets.max_expansions and time_budget_s."""
        goal = len(self.poses) - 1
        stack: list = [root]
        while stack:
            if self.expanded >= budgets.max_expansions:
                return None, Refusal(RefusalKind.NODE_BUDGET, count=self.expanded)
            if t0.over(budgets):
                return None, Refusal(RefusalKind.TIME_BUDGET, limit=budgets.time_budget_s)
            item = stack.pop()
            if isinstance(item, _SpaceChild):
                key = (item.parent.depth + 1, item.contacts)
                if key in self.visited:
                    continue
                self.visited.add(key)
                node, why = self.feasible(item)
                if node is None:
                    self.refused[why.coarse()] += 1
                    continue
            else:
                node = item
            if node.depth == goal:
                return node, None
            self.expanded += 1
            children = self.neighbors(node)
            self.generated += len(children)
            stack.extend(reversed(children))
        return None, Refusal(RefusalKind.TREE_EXHAUSTED, count=self.expanded)

    def plan_nodes(self, leaf: _SpaceNode) -> tuple[SpaceContactNode, ...]:
        path = []
        while leaf is not None:
            path.append(leaf)
            leaf = leaf.parent
        return tuple(
            SpaceContactNode(
                object_pose=self.poses[n.depth].copy(),
                q=n.q.copy(),
                faces=tuple(BOX_FACE_NAMES[self.face[c]] for c in n.contacts),
                p_BC=self.p_BC[list(n.contacts)].copy(),
                switching_finger=n.switching_finger,
                closure_margin=float(self.closed(n.contacts).margin),
                stance_torque=None if n.depth == 0 else n.stance_torque,
                stance_push_capacity=None if n.depth == 0 else n.push,
                stance_margin=n.stance_mu == self.mu_hold,
                stance_mu=n.stance_mu,
            )
            for n in reversed(path)
        )


def find_space_contact_plan(
    scene, goal_quaternion, config: SearchConfig, mu: float, root: SpaceRoot | None = None
) -> SpaceContactPlan:
    """Algorithm 1 in space: a contact sequence for the hand in space `scene` (scene.spatial.SpaceScene)
    turning its box from the start pose (or the measured `root`'s pose and grasp) to the unit quaternion
    `goal_quaternion` [w, x, y, z], at friction mu (mu_plan), or why none was found."""
    t0 = SearchClock.start(config)
    goal = tuple(float(v) for v in goal_quaternion)
    search = _SpaceSearch(scene, goal, config, mu, root)
    leaf, last, searched, candidates = None, None, 0, 0
    for frictions, budgets in search.passes():
        search.begin_pass(frictions)
        roots = search.roots()
        candidates += len(roots)
        for root in roots:
            searched += 1
            leaf, why = search.run(root, t0, budgets)
            last = AtRoot(tuple(float(c) for c in root.contacts), why) if why else None
            if leaf is not None or (why and why.kind in (RefusalKind.TIME_BUDGET, RefusalKind.NODE_BUDGET)):
                break
        if leaf is not None:
            break
    stats = SearchStats(
        expanded=search.expanded,
        generated=search.generated,
        lp_calls=search.lp_calls,
        ik_calls=search.reach.ik_calls,
        time_s=t0.elapsed(),
        initial_grasps_searched=searched,
        initial_grasp_candidates=candidates,
    )
    common = dict(
        goal=goal, stats=stats, mu_plan=mu, max_segment_rotation=SPACE_MAX_SEGMENT_ROTATION, mu_margin=search.mu_hold
    )
    if leaf is not None:
        return SpaceContactPlan(success=True, nodes=search.plan_nodes(leaf), **common)
    refusal = NoPlan(
        searched=stats.initial_grasps_searched,
        candidates=candidates,
        skipped=0,
        first_skipped=None,
        last_searched=last,
        mu_plan=mu,
        refused=tuple(search.refused.most_common(5)),
    )
    return SpaceContactPlan(success=False, refusal=refusal, **common)


def space_initial_grasp(scene, goal_quaternion, config: SearchConfig, mu: float) -> SpaceContactPlan:
    """A one-node SpaceContactPlan holding the search's best-ranked initial grasp for the goal (_SpaceSearch.roots,
    no tree search), for general CITO in space, as the plane's `cito` takes the initial-grasp chooser's first
    choice; or, when no grasp at the start qualifies, why."""
    t0 = SearchClock.start(config)
    goal = tuple(float(v) for v in goal_quaternion)
    search = _SpaceSearch(scene, goal, config, mu)
    roots = search.roots()
    stats = SearchStats(
        lp_calls=search.lp_calls,
        ik_calls=search.reach.ik_calls,
        time_s=t0.elapsed(),
        initial_grasp_candidates=len(roots),
    )
    common = dict(
        goal=goal, stats=stats, mu_plan=mu, max_segment_rotation=SPACE_MAX_SEGMENT_ROTATION, mu_margin=search.mu_hold
    )
    if roots:
        return SpaceContactPlan(success=True, nodes=search.plan_nodes(roots[0]), **common)
    refusal = NoPlan(0, 0, 0, None, None, mu, tuple(search.refused.most_common(5)))
    return SpaceContactPlan(success=False, refusal=refusal, **common)
