"""Kinematic reachability of fingertip contacts (paper Sec. III-A, IsFeasible).

A contact at arclength s of the box at object pose x is reachable by finger i when the
fingertip sphere touches the box there: the sphere centre p_WF = p_WC + r n_W is reached
within the joint limits (Drake `InverseKinematics` on the scene's plant, SNOPT), and
neither link of the finger penetrates the box.

Two stages keep the search cheap:
- `closed_form` solves the 2-link IK analytically (`kinematics.TwoLinkFinger.ik_solutions`,
  both elbow branches, q1 wrapped into its limits). A planar 2-link chain has no other
  solutions, so when none lies within the limits the contact is unreachable and Drake IK
  would fail too: this is an exact filter.
- `solve` runs Drake IK seeded with the closed-form answer and keeps its joint angles.

Fingers against each other (`path_refusal`): the same exact planar geometry between two
fingers' link boxes and fingertip spheres (trajectotree.scene.finger_clearance), sampled on the
straight joint-space path from a node's parent (a node's own joint angles: search.tree), kept at least
search.finger_clearance apart, since the simulation's fingers collide (trajectotree.search.tree).

Collision test (links vs object): an exact planar separating-axis test between the object's
convex polygon (trajectotree.geometry; the box keeps its closed form) and each link's
collision box from the SDF (scene.FingerGeometry.link_boxes: read from SceneGraph's inspector,
expressed in the frame of the joint that moves it). All collision geometry is centred on the z = 0 plane,
so planar overlap is 3D overlap; tests/test_reach.py checks it against SceneGraph's
signed-distance queries. The fingertip sphere is not tested: it touches by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver

from trajectotree.geometry import ConvexPolygon, box_to_world, rotation_2d
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.scene.finger_clearance import (
    FingerCapsules,
    fingers_clear,
    interpolate_joints,
    pair_distances,
    sweep_bound,
)
from trajectotree.scene.kinematics import first_solution
from trajectotree.scene.plant import Scene

IK_TOLERANCE = 1e-6  # m, fingertip position tolerance of the IK constraint
# m, the most any point of two fingers moves between the samples of the straight joint-space path between
# two nodes at which they are tested against each other: half the fingertip sphere's radius
PATH_RESOLUTION = 0.005
KEY_DIGITS = 9  # poses and arclengths equal to 1e-9 share a cache entry


@dataclass(frozen=True)
class FingerReach:
    reachable: bool
    q: np.ndarray  # (2,) rad, the finger's joint angles (nan when unreachable)
    refusal: Refusal | None = None  # why not (OUT_OF_REACH, LINKS_PENETRATE or IK_FAILED), None when reachable


def rectangles_overlap_polygon(
    polygon: ConvexPolygon, center, angle, half_length: float, half_width: float
) -> np.ndarray:
    """Separating-axis test of rectangles against a convex polygon, all in the polygon's frame:
    centres (k, 2), angles (k,) of their x axes, half sizes. (k,) bool, touching counts as not
    overlapping. Two convex polygons are disjoint iff one of their edge normals separates them,
    so the candidate axes are the polygon's face normals and the rectangle's two axes; for the
    box (two of each) they reduce to the closed form below."""
    c = np.atleast_2d(np.asarray(center, dtype=float))
    g = np.broadcast_to(np.asarray(angle, dtype=float), c.shape[:1])
    ux_s, uy_s = np.cos(g), np.sin(g)
    hl, hw = half_length, half_width
    if polygon.is_box:
        a, b = polygon.box_half
        cx, cy = c[:, 0], c[:, 1]
        ux, uy = np.abs(ux_s), np.abs(uy_s)
        return (
            (np.abs(cx) < a + hl * ux + hw * uy)
            & (np.abs(cy) < b + hl * uy + hw * ux)
            & (np.abs(cx * ux_s + cy * uy_s) < hl + a * ux + b * uy)
            & (np.abs(-cx * uy_s + cy * ux_s) < hw + a * uy + b * ux)
        )
    n, v = polygon.normals, polygon.vertices
    low = polygon.back_offsets  # (V,): the polygon spans [low_f, offset_f] along n_f
    centre = c @ n.T  # (k, V)
    radius = hl * np.abs(ux_s[:, None] * n[:, 0] + uy_s[:, None] * n[:, 1]) + hw * np.abs(
        -uy_s[:, None] * n[:, 0] + ux_s[:, None] * n[:, 1]
    )  # (k, V)
    overlap = np.all((centre - radius < polygon.offsets) & (centre + radius > low), axis=1)
    # the rectangle's axes u (half size hl) and v (hw)
    for axis, half in ((np.stack([ux_s, uy_s], 1), hl), (np.stack([-uy_s, ux_s], 1), hw)):
        proj = axis @ v.T  # (k, V)
        mid = np.einsum("ka,ka->k", c, axis)
        overlap &= (mid - half < proj.max(axis=1)) & (mid + half > proj.min(axis=1))
    return overlap


def path_samples(fingers, q_from, q_to, tip_radius: float, clearance: float, ends):
    """(pairs, samples (S, 2F)): the pairs of fingers whose motion on the straight joint-space path
    from q_from to q_to (2F,) could bring them within `clearance` m (half the two ends' gaps, `ends`
    {(i, j): (m at q_from, m at q_to)}, less the most the two fingers' points move, sweep_bound: the
    least the gap can be on the way), and the path between its ends sampled every PATH_RESOLUTION
    of the most any of them moves (none when no pair is near)."""
    q_from, q_to = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    moves = [
        sweep_bound(f, q_from[2 * i : 2 * i + 2], q_to[2 * i : 2 * i + 2], tip_radius) for i, f in enumerate(fingers)
    ]
    motion = {(i, j): moves[i] + moves[j] for i, j in ends}
    near = [pair for pair, (a, b) in ends.items() if 0.5 * (a + b - motion[pair]) < clearance]
    if not near:
        return [], np.zeros((0, len(q_to)))
    steps = max(2, int(np.ceil(max(motion[pair] for pair in near) / PATH_RESOLUTION)))
    return near, interpolate_joints(np.stack([q_from, q_to]), steps)[1:-1]


def samples_refusal(
    fingers, samples, tip_radius: float, clearance: float, pairs, capsules: FingerCapsules | None = None
) -> Refusal | None:
    """FINGERS_COLLIDE (count 1: on the path to a node) naming a pair of `pairs` that comes within
    `clearance` m at one of the joint angles `samples` (S, 2F), None when none does: the exact
    distance only where the capsules' cheaper bound (`capsules`, the fingers' FingerCapsules, built
    here when None) does not already clear them."""
    capsules = FingerCapsules.of(fingers, tip_radius) if capsules is None else capsules
    bounds = capsules.lower_bounds(samples, pairs)
    unsure = [pair for pair in pairs if bounds[pair].min() < clearance]
    if not unsure:
        return None
    rows = np.any([bounds[pair] < clearance for pair in unsure], axis=0)
    for pair, gap in pair_distances(fingers, samples[rows], tip_radius, pairs=unsure).items():
        if not np.all(fingers_clear(gap, clearance)):
            return Refusal(RefusalKind.FINGERS_COLLIDE, fingers=pair, limit=clearance, count=1)
    return None


def path_refusal(
    fingers, q_from, q_to, tip_radius: float, clearance: float, ends=None, capsules: FingerCapsules | None = None
) -> Refusal | None:
    """samples_refusal on the straight joint-space path from q_from to q_to (2F,), both ends clear
    (path_samples); `ends`: the pairs' gaps at both ends when known (the search memoizes them), else
    computed here; `capsules`: the fingers' FingerCapsules when built already (the search's)."""
    if ends is None:
        ends = pair_distances(fingers, np.stack([q_from, q_to]), tip_radius)
    near, samples = path_samples(fingers, q_from, q_to, tip_radius, clearance, ends)
    return samples_refusal(fingers, samples, tip_radius, clearance, near, capsules) if near else None


class Reachability:
    """Reachability queries for one scene, cached by (object pose, finger, arclength)."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.boundary = scene.config.shape
        self.tip_radius = scene.tip_radius
        self.fingers = scene.fingers
        self._iks = [self._make_ik(i) for i in range(scene.num_fingers)]
        self._solver = SnoptSolver()
        self._cache: dict[tuple, FingerReach] = {}
        self._closed_form_cache: dict[tuple, FingerReach] = {}
        self._points: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self.ik_calls = 0  # Drake IK queries so far (cache hits and closed-form rejections excluded)

    # -- geometry -------------------------------------------------------------------------
    def contact(self, arclength: float) -> tuple[np.ndarray, np.ndarray]:
        """(p_BC, n_B) at `arclength`, memoized (the search asks for the same few hundred)."""
        key = round(float(arclength) % self.boundary.perimeter, KEY_DIGITS)
        if key not in self._points:
            self._points[key] = self.boundary.point(key)
        return self._points[key]

    def tip_target(self, pose, arclength: float) -> np.ndarray:
        """p_WF: where the fingertip centre must be to touch the box at `arclength`."""
        p_BC, n_B = self.contact(arclength)
        return box_to_world(pose, p_BC + self.tip_radius * n_B)

    def _joint_frames(self, finger: int, q):
        """(p_WJ, angle_WJ) of the joint-1 and joint-2 frames at joint angles q."""
        f = self.fingers[finger]
        a1, a12, r1, _ = f.links_one(q[0], q[1])
        return (f.p_W_base, a1), (f.p_W_base + np.array(r1), a12)

    def link_polygons(self, finger: int, q) -> list[np.ndarray]:
        """Corners (4, 2) in W of the finger's link collision boxes at joint angles q."""
        return [
            rect.corners(p_WJ, angle)
            for rect, (p_WJ, angle) in zip(self.fingers[finger].link_boxes, self._joint_frames(finger, q))
            if rect is not None
        ]

    def links_penetrate(self, pose, finger: int, q) -> bool:
        """True when a link collision box of `finger` at q overlaps the object at `pose`."""
        R_BW, p_WB = rotation_2d(-pose[2]), np.asarray(pose[:2], dtype=float)
        for rect, (p_WJ, angle_WJ) in zip(self.fingers[finger].link_boxes, self._joint_frames(finger, q)):
            if rect is None:  # a link without collision geometry
                continue
            p_WG = p_WJ + rotation_2d(angle_WJ) @ rect.p_JG
            if rectangles_overlap_polygon(
                self.boundary,
                R_BW @ (p_WG - p_WB),
                angle_WJ + rect.angle_JG - pose[2],
                rect.half_length,
                rect.half_width,
            )[0]:
                return True
        return False

    # -- vectorized closed form (many arclengths at one pose) ---------------------------------
    def contacts(self, arclengths) -> tuple[np.ndarray, np.ndarray]:
        """(p_BC (k, 2), n_B (k, 2)) for an array of arclengths (vectorized ConvexPolygon.point)."""
        return self.boundary.points(arclengths)

    def closed_form_many(self, poses, finger: int, arclengths) -> np.ndarray:
        """`closed_form` for many contacts at once: `poses` (3,) or one per contact (k, 3).
        Joint angles (k, 2), nan rows where the contact is unreachable (same solution choice
        as `closed_form`)."""
        f = self.fingers[finger]
        p_BC, n_B = self.contacts(arclengths)
        poses = np.broadcast_to(np.asarray(poses, dtype=float), (len(p_BC), 3))
        p_BF = p_BC + self.tip_radius * n_B
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        p_WF = poses[:, :2] + np.stack([c * p_BF[:, 0] - s * p_BF[:, 1], s * p_BF[:, 0] + c * p_BF[:, 1]], axis=1)
        candidates, valid = f.ik_candidates(p_WF)  # (6, k, 2), (6, k): the order of ik_solutions
        rows = np.broadcast_to(poses, (len(candidates), *poses.shape))[valid]
        valid[valid] = ~self._links_penetrate_many(rows, finger, candidates[valid])
        return first_solution(candidates, valid)

    def _links_penetrate_many(self, poses: np.ndarray, finger: int, q: np.ndarray) -> np.ndarray:
        """Vectorized links_penetrate: object poses (k, 3), joint angles (k, 2)."""
        f = self.fingers[finger]
        a1, a12 = f.angles(q)
        elbow = f.elbow(q)
        ct, st = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        hit = np.zeros(len(q), dtype=bool)
        for rect, origin, angle in zip(self.fingers[finger].link_boxes, (f.p_W_base, elbow), (a1, a12)):
            if rect is None:
                continue
            c, s = np.cos(angle), np.sin(angle)
            rel = (
                origin
                + np.stack([c * rect.p_JG[0] - s * rect.p_JG[1], s * rect.p_JG[0] + c * rect.p_JG[1]], axis=1)
                - poses[:, :2]
            )
            centre = np.stack([ct * rel[:, 0] + st * rel[:, 1], -st * rel[:, 0] + ct * rel[:, 1]], axis=1)  # in B
            hit |= rectangles_overlap_polygon(
                self.boundary, centre, angle + rect.angle_JG - poses[:, 2], rect.half_length, rect.half_width
            )
        return hit

    # -- IK -------------------------------------------------------------------------------
    def _make_ik(self, i: int):
        """IK for finger i alone: the box and the other fingers are locked in the context."""
        plant, scene = self.scene.plant, self.scene
        diagram_context = scene.diagram.CreateDefaultContext()
        context = plant.GetMyMutableContextFromRoot(diagram_context)
        plant.GetJointByName("box_planar").Lock(context)
        for k, finger in enumerate(scene.hand_description.fingers):
            if k != i:
                for name in finger.joints:
                    plant.GetJointByName(name, scene.hand).Lock(context)
        ik = InverseKinematics(plant, context, with_joint_limits=True)
        position = ik.AddPositionConstraint(
            scene.tip_frame(i), np.zeros(3), plant.world_frame(), np.zeros(3), np.zeros(3)
        )
        indices = scene.hand_q_indices[2 * i : 2 * i + 2]
        return ik, position, diagram_context, indices

    def _drake_ik(self, finger: int, p_WF, q_guess) -> np.ndarray | None:
        ik, position, diagram_context, indices = self._iks[finger]
        target = np.array([p_WF[0], p_WF[1], 0.0])
        position.evaluator().set_bounds(target - IK_TOLERANCE, target + IK_TOLERANCE)
        guess = np.zeros(self.scene.plant.num_positions())
        guess[indices] = q_guess
        self.ik_calls += 1
        # A seed that already satisfies every constraint of the IK program (no cost) is what SNOPT
        # returns from it, unchanged (300 of 300 closed-form seeds, bit for bit); checking it costs
        # ~30 us where the solve costs ~450 us, so SNOPT runs only for a seed that misses them.
        if ik.prog().CheckSatisfied(ik.prog().GetAllConstraints(), guess, 0.0):
            return guess[indices]
        result = self._solver.Solve(ik.prog(), guess)
        return result.GetSolution(ik.q())[indices] if result.is_success() else None

    # -- queries --------------------------------------------------------------------------
    def _key(self, pose, finger: int, arclength: float) -> tuple:
        return (
            tuple(round(float(v), KEY_DIGITS) for v in pose),
            finger,
            round(float(arclength) % self.boundary.perimeter, KEY_DIGITS),
        )

    def closed_form(self, pose, finger: int, arclength: float) -> FingerReach:
        """Closed-form reachability (joint limits and link collision), no solver call; memoized."""
        key = self._key(pose, finger, arclength)
        if key not in self._closed_form_cache:
            self._closed_form_cache[key] = self._closed_form(pose, finger, arclength)
        return self._closed_form_cache[key]

    def _closed_form(self, pose, finger: int, arclength: float) -> FingerReach:
        solutions = self.fingers[finger].ik_solutions(self.tip_target(pose, arclength))
        if not solutions:
            return FingerReach(False, np.full(2, np.nan), Refusal(RefusalKind.OUT_OF_REACH))
        free = [q for q in solutions if not self.links_penetrate(pose, finger, q)]
        if not free:
            return FingerReach(False, solutions[0], Refusal(RefusalKind.LINKS_PENETRATE))
        return FingerReach(True, free[0])

    def solve(self, pose, finger: int, arclength: float, seed: np.ndarray | None = None) -> FingerReach:
        """Drake IK (seeded by the closed form) + collision test: the node's joint angles; memoized.
        `seed`: the closed form's joint angles when the caller has them (closed_form_many's), which
        spares computing them again."""
        key = self._key(pose, finger, arclength)
        if key not in self._cache:
            self._cache[key] = self._solve(pose, finger, arclength, seed)
        return self._cache[key]

    def _solve(self, pose, finger: int, arclength: float, seed: np.ndarray | None = None) -> FingerReach:
        guess = self.closed_form(pose, finger, arclength) if seed is None else FingerReach(True, seed)
        if not guess.reachable:
            return guess
        q = self._drake_ik(finger, self.tip_target(pose, arclength), guess.q)
        if q is None:
            return FingerReach(False, np.full(2, np.nan), Refusal(RefusalKind.IK_FAILED))
        if self.links_penetrate(pose, finger, q):
            return FingerReach(False, q, Refusal(RefusalKind.LINKS_PENETRATE))
        return FingerReach(True, q)
