"""Which contacts on the box a finger of a hand in space reaches: Drake InverseKinematics with the
fingertip sphere's centre r out from the contact along the face's normal, within the joint limits,
the finger's links (every collision geometry of its bodies but the fingertip sphere) at least
`clearance` from the box. The box is held at its pose; the other fingers are left out (a per-finger
question: which faces each finger reaches, what the scene reports).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver

from trajectotree.geometry import BOX_FACE_NAMES, box_face_grid
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
