"""Which contacts on the box a finger of a hand in space reaches: Drake InverseKinematics with the
fingertip sphere's centre r out from the contact along the face's normal, within the joint limits,
the finger's links (every collision geometry of its bodies but the fingertip sphere) at least
`clearance` from the box. The box is held at its pose; the other fingers are left out (a per-finger
question: which faces each finger reaches, what the scene reports).

`SpatialReach` answers the search's question (trajectotree.search.space_tree), cheap checks first:
1. the fingertip workspace: the finger's fingertip centre over a grid of its joint ranges (forward
   kinematics, `WORKSPACE_SAMPLES` per joint); a target farther from every sample than
   the most a fingertip moves within half a grid step (sum_j of joint j's largest lever times half its
   step) is out of reach within the limits, exactly; the nearest sample seeds the IK;
2. IK without collision (the fingertip centre on its target in the box frame, built once per finger,
   its bounds updated), from the parent node's angles (warm start) and from the nearest sample;
3. SceneGraph's signed distances at that solution: links clear of the box by `clearance` ends it;
4. else IK with the links kept `clearance` from the box (a distance constraint per link and box).
A node's four fingers are then checked together (`links_clear`): no two fingers' geometries within
`clearance` of each other, no link within it of the box. Refusals are typed (trajectotree.refusal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver

from trajectotree.geometry import BOX_FACE_NAMES, box_face_grid
from trajectotree.refusal import Refusal, RefusalKind
from trajectotree.scene.spatial import START_POSE, SpaceScene

CLEARANCE = 0.002  # m, the links from the box
POSITION_TOLERANCE = 1e-4  # m, the fingertip centre from its target
STARTS = 4  # IK starts per contact: the joint ranges' middle, then uniform random (seed 0); 16 and 48 found no more
GRID_PER_SIDE = 3  # contacts per face: 3 x 3


def box_transform(pose) -> RigidTransform:
    """X_WB from the box's [qw, qx, qy, qz, px, py, pz]."""
    from pydrake.common.eigen_geometry import Quaternion

    q = np.asarray(pose, dtype=float)
    return RigidTransform(Quaternion(q[:4] / np.linalg.norm(q[:4])), q[4:])


class FingerIk:
    """IK for one finger of a SpaceScene against its box."""

    def __init__(self, scene: SpaceScene, finger: int, clearance: float = CLEARANCE):
        self.scene, self.finger = scene, finger
        plant, inspector = scene.plant, scene.scene_graph.model_inspector()
        bodies = {
            plant.GetJointByName(n, scene.hand).child_body().index() for n in scene.hand_file.fingers[finger].joints
        }
        box_geometry = plant.GetCollisionGeometriesForBody(plant.GetBodyByName("box", scene.box))
        self.pairs = [
            (g, b)
            for index in sorted(bodies)
            for g in plant.GetCollisionGeometriesForBody(plant.get_body(index))
            if not isinstance(inspector.GetShape(g), Sphere)  # the fingertip may touch
            for b in box_geometry
        ]
        self.clearance = clearance
        n = len(scene.fingers[finger].q_lower)
        self.columns = scene.hand_q_indices[finger * n : (finger + 1) * n]
        lower, upper = scene.fingers[finger].q_lower, scene.fingers[finger].q_upper
        self.starts = [(lower + upper) / 2, *np.random.default_rng(0).uniform(lower, upper, size=(STARTS - 1, n))]
        self.solver = SnoptSolver()

    def solve(self, pose, p_WF) -> np.ndarray | None:
        """The finger's joint angles (n,) that put its fingertip centre at p_WF (3,) with the box at
        `pose`, or None."""
        plant = self.scene.plant
        context = self.scene.diagram.CreateDefaultContext()
        ik = InverseKinematics(plant, plant.GetMyMutableContextFromRoot(context))
        q = ik.q()
        box = self.scene.box_q_indices
        ik.prog().AddBoundingBoxConstraint(pose, pose, q[box])
        others = np.setdiff1d(np.arange(plant.num_positions()), np.r_[box, self.columns])
        ik.prog().AddBoundingBoxConstraint(0.0, 0.0, q[others])
        target = np.asarray(p_WF, dtype=float)
        ik.AddPositionConstraint(
            self.scene.tip_frame(self.finger),
            np.zeros(3),
            plant.world_frame(),
            target - POSITION_TOLERANCE,
            target + POSITION_TOLERANCE,
        )
        for pair in self.pairs:
            ik.AddDistanceConstraint(pair, self.clearance, np.inf)
        guess = np.zeros(plant.num_positions())
        guess[box] = pose
        for start in self.starts:
            guess[self.columns] = start
            result = self.solver.Solve(ik.prog(), guess)
            if result.is_success():
                return result.GetSolution(q)[self.columns]
        return None


@dataclass(frozen=True)
class FaceReach:
    """How many of each face's grid contacts each finger reaches, the box at one pose."""

    counts: np.ndarray  # (F, 6) of per_face contacts, faces in geometry.BOX_FACE_NAMES order
    per_face: int

    def fingers_per_face(self) -> np.ndarray:
        """(6,) how many fingers reach each face at all."""
        return np.sum(self.counts > 0, axis=0)

    def to_json(self) -> dict:
        return {
            "faces": list(BOX_FACE_NAMES),
            "contacts_per_face": self.per_face,
            "reachable_contacts": self.counts.tolist(),
            "fingers_per_face": self.fingers_per_face().tolist(),
        }


def face_reach(scene: SpaceScene, pose=START_POSE) -> FaceReach:
    """Each finger's reachable contacts on each face's 3 x 3 grid (a fingertip radius in from the
    edges), the box at `pose` ([qw, qx, qy, qz, px, py, pz])."""
    X_WB = box_transform(pose)
    p_BC, n_B = box_face_grid(scene.object.half, GRID_PER_SIDE, scene.tip_radius)
    R = X_WB.rotation().matrix()
    targets = (p_BC + scene.tip_radius * n_B[:, None, :]) @ R.T + X_WB.translation()  # (6, 9, 3) in W
    counts = np.zeros((scene.num_fingers, len(n_B)), dtype=int)
    for i in range(scene.num_fingers):
        ik = FingerIk(scene, i)
        for f, face in enumerate(targets):
            counts[i, f] = sum(ik.solve(pose, p) is not None for p in face)
    return FaceReach(counts=counts, per_face=GRID_PER_SIDE**2)


def fingertip_workspace(scene: SpaceScene, samples: int = 9) -> np.ndarray:
    """(F, 2, 3) m, the low and high corners of the box that bounds each fingertip centre over a
    samples^n grid of its joint ranges (forward kinematics, links' collisions ignored)."""
    out = []
    for finger in scene.fingers:
        axes = [np.linspace(lo, hi, samples) for lo, hi in zip(finger.q_lower, finger.q_upper)]
        q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
        p = finger.fingertip(q)
        out.append([p.min(axis=0), p.max(axis=0)])
    return np.array(out)


# -- the search's reach: cheap checks first --------------------------------------------------------
WORKSPACE_SAMPLES = 21  # per joint: 9261 fingertip samples a finger, a bound of about 3 cm (see SpatialReach)
SEEDS_WITH_COLLISION = 3  # nearest workspace samples also tried as IK seeds once the links must keep clear


@dataclass(frozen=True)
class SpaceFingerReach:
    """One finger on one contact at one pose: its joint angles, or why not (OUT_OF_REACH, IK_FAILED,
    LINKS_PENETRATE)."""

    q: np.ndarray | None  # (n,) rad
    refusal: Refusal | None = None

    @property
    def reachable(self) -> bool:
        return self.refusal is None


@dataclass(frozen=True)
class _Workspace:
    """One finger's fingertip samples over a grid of its joint ranges, and how far off the grid a
    reachable point can be (m)."""

    q: np.ndarray  # (S, n) rad
    tips: np.ndarray  # (S, 3) m, the fingertip centres in W
    bound: float  # m

    def nearest(self, p_WF, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(distances (k,) m, indices (k,)) of the k samples nearest to p_WF, nearest first (a brute-force
        search over the few thousand samples: about as fast as a k-d tree here, and no scipy for the planner)."""
        d = np.linalg.norm(self.tips - p_WF, axis=1)
        nearest = np.argpartition(d, k)[:k]
        nearest = nearest[np.argsort(d[nearest])]
        return d[nearest], nearest


def _workspace(finger, samples: int) -> _Workspace:
    axes = [np.linspace(lo, hi, samples) for lo, hi in zip(finger.q_lower, finger.q_upper)]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    points, _, tips = finger.frames(q)
    # joint j moves the fingertip by at most (its largest distance from joint j's axis) x (the angle)
    levers = np.linalg.norm(tips[:, None, :] - points, axis=2).max(axis=0)
    steps = (finger.q_upper - finger.q_lower) / (samples - 1)
    return _Workspace(q=q, tips=tips, bound=float(np.sum(levers * steps / 2)))


class _FingerPrograms:
    """One finger's IK programs, built once: its fingertip centre at p_BF in the box frame B, the box
    at a given pose, without and with its links `clearance` from the box; `solve` updates the bounds."""

    def __init__(self, scene: SpaceScene, finger: int, pairs, clearance: float):
        plant = scene.plant
        box_frame = plant.GetBodyByName("box", scene.box).body_frame()
        n = len(scene.fingers[finger].q_lower)
        self.columns = scene.hand_q_indices[finger * n : (finger + 1) * n]
        self.box_columns = scene.box_q_indices
        self.programs = []
        for with_collision in (False, True):
            context = scene.diagram.CreateDefaultContext()
            ik = InverseKinematics(plant, plant.GetMyMutableContextFromRoot(context))
            others = np.setdiff1d(np.arange(plant.num_positions()), np.r_[self.box_columns, self.columns])
            ik.prog().AddBoundingBoxConstraint(0.0, 0.0, ik.q()[others])
            box = ik.prog().AddBoundingBoxConstraint(START_POSE, START_POSE, ik.q()[self.box_columns])
            tip = ik.AddPositionConstraint(scene.tip_frame(finger), np.zeros(3), box_frame, np.zeros(3), np.zeros(3))
            if with_collision:
                for pair in pairs:
                    ik.AddDistanceConstraint(pair, clearance, np.inf)
            self.programs.append((ik, box.evaluator(), tip.evaluator()))
        self.solver = SnoptSolver()

    def solve(self, with_collision: bool, pose, p_BF, seeds) -> np.ndarray | None:
        ik, box, tip = self.programs[with_collision]
        box.set_bounds(pose, pose)
        tip.set_bounds(p_BF - POSITION_TOLERANCE, p_BF + POSITION_TOLERANCE)
        guess = np.zeros(len(ik.q()))
        guess[self.box_columns] = pose
        for seed in seeds:
            guess[self.columns] = seed
            result = self.solver.Solve(ik.prog(), guess)
            if result.is_success():
                return result.GetSolution(ik.q())[self.columns]
        return None


class SpatialReach:
    """Reach of contacts on the box by the fingers of a SpaceScene (the module doc's cheap checks
    first), and the clearance of a whole hand's configuration; `ik_calls` counts Drake IK solves."""

    def __init__(self, scene: SpaceScene, clearance: float = CLEARANCE, samples: int = WORKSPACE_SAMPLES):
        self.scene, self.clearance = scene, clearance
        plant, inspector = scene.plant, scene.scene_graph.model_inspector()
        self.finger_of: dict = {}  # GeometryId -> (finger, whether it is the fingertip sphere)
        for i, entry in enumerate(scene.hand_file.fingers):
            for name in entry.joints:
                body = plant.GetJointByName(name, scene.hand).child_body()
                for g in plant.GetCollisionGeometriesForBody(body):
                    self.finger_of[g] = (i, isinstance(inspector.GetShape(g), Sphere))
        box_geometry = plant.GetCollisionGeometriesForBody(plant.GetBodyByName("box", scene.box))
        self.workspaces = [_workspace(f, samples) for f in scene.fingers]
        self.programs = [
            _FingerPrograms(
                scene,
                i,
                [(g, b) for g, (j, tip) in self.finger_of.items() if j == i and not tip for b in box_geometry],
                clearance,
            )
            for i in range(scene.num_fingers)
        ]
        self._context = scene.diagram.CreateDefaultContext()
        self.ik_calls = 0

    def solve(self, pose, finger: int, p_BF, seed=None) -> SpaceFingerReach:
        """Finger `finger`'s joint angles with its fingertip centre at p_BF (3,) in the box frame, the
        box at `pose` [qw, qx, qy, qz, px, py, pz], its links clear of the box; `seed` (n,): the
        angles to start from first (the parent node's)."""
        p_WF = box_transform(pose) @ np.asarray(p_BF, dtype=float)
        workspace = self.workspaces[finger]
        distance, nearest = workspace.nearest(p_WF, SEEDS_WITH_COLLISION)
        if distance[0] > workspace.bound:
            return SpaceFingerReach(None, Refusal(RefusalKind.OUT_OF_REACH, fingers=(finger,)))
        seeds = ([] if seed is None else [np.asarray(seed, dtype=float)]) + [workspace.q[nearest[0]]]
        program = self.programs[finger]
        self.ik_calls += 1
        q = program.solve(False, pose, p_BF, seeds)
        if q is None:
            return SpaceFingerReach(None, Refusal(RefusalKind.IK_FAILED, fingers=(finger,)))
        if self.link_box_distance(pose, finger, q) >= self.clearance:
            return SpaceFingerReach(q)
        self.ik_calls += 1
        clear = program.solve(True, pose, p_BF, [q, *seeds, *workspace.q[nearest[1:]]])
        if clear is None:
            return SpaceFingerReach(None, Refusal(RefusalKind.LINKS_PENETRATE, fingers=(finger,)))
        return SpaceFingerReach(clear)

    def _pairs(self, pose, q_by_finger: dict, within: float):
        """SceneGraph's signed-distance pairs within `within` m, the box at `pose` and the fingers at
        q_by_finger {finger: (n,)} (the others at zero angles)."""
        q = np.zeros((self.scene.num_fingers, len(self.scene.fingers[0].q_lower)))
        for i, angles in q_by_finger.items():
            q[i] = angles
        plant = self.scene.plant
        plant.SetPositions(plant.GetMyMutableContextFromRoot(self._context), self.scene.positions(pose, q))
        query = self.scene.scene_graph.get_query_output_port().Eval(
            self.scene.scene_graph.GetMyContextFromRoot(self._context)
        )
        return query.ComputeSignedDistancePairwiseClosestPoints(within)

    def link_box_distance(self, pose, finger: int, q) -> float:
        """m, the least signed distance from a link of `finger` (not its fingertip sphere) to the box,
        `clearance` or more when none is that close."""
        out = self.clearance
        for pair in self._pairs(pose, {finger: q}, self.clearance):
            for mine, other in ((pair.id_A, pair.id_B), (pair.id_B, pair.id_A)):
                if self.finger_of.get(mine) == (finger, False) and other not in self.finger_of:
                    out = min(out, pair.distance)
        return out

    def links_clear(self, pose, q) -> Refusal | None:
        """Why the hand at joint angles q (F, n), the box at `pose`, is refused (None when it is not):
        two fingers within `clearance` of each other (FINGERS_COLLIDE) or a link within it of the box
        (LINKS_PENETRATE)."""
        for pair in self._pairs(pose, dict(enumerate(q)), self.clearance):
            a, b = self.finger_of.get(pair.id_A), self.finger_of.get(pair.id_B)
            if a is not None and b is not None and a[0] != b[0]:
                return Refusal(RefusalKind.FINGERS_COLLIDE, fingers=(a[0], b[0]), limit=self.clearance)
            link = a if b is None else b if a is None else None
            if link is not None and not link[1]:
                return Refusal(RefusalKind.LINKS_PENETRATE, fingers=(link[0],), limit=self.clearance)
        return None
