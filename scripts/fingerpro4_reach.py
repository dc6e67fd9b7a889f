"""Which faces of a cube at the grasp point each finger of fingerpro4 reaches, for several mounts.

For a 6.5 cm cube at the grasp point G (axis-aligned), each face's 3 x 3 grid of contacts (1 cm in
from the edges: at -0.0225, 0, +0.0225 m), and one finger at 0 deg about the vertical: a contact is
reachable when Drake's InverseKinematics (SNOPT, from several starts) puts the fingertip sphere's
centre 1 cm out from the contact along the face's normal (0.1 mm tolerance) within the joint limits
with the finger's links at least 2 mm from the cube (the fingertip sphere itself may touch). The cube
and its grid are symmetric under a quarter turn about the vertical, so finger i (at 90 i deg)
reaches face f rotated by 90 i deg exactly as finger 0 reaches f: one finger is solved, and the
table lists the faces each finger reaches through that symmetry.

    python scripts/fingerpro4_reach.py            # the candidate mounts, about a minute each
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.geometry import Box, CollisionFilterDeclaration, GeometrySet, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.solvers import SnoptSolver
from pydrake.systems.framework import DiagramBuilder

_spec = importlib.util.spec_from_file_location("fingerpro4_model", Path(__file__).with_name("fingerpro4_model.py"))
model = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(model)

CUBE_SIZE = 0.065  # m, the field's cube
GRID = (-0.0225, 0.0, 0.0225)  # m, contacts along each face's two tangent axes (1 cm in from the edges)
CLEARANCE = 0.002  # m, links from the cube
TOLERANCE = 1e-4  # m, fingertip position
STARTS = 4  # IK starts per contact: the joint ranges' middle, then uniform random (seed 0)
# faces by their outward normal in G; name, normal
FACES = (
    ("+x", (1, 0, 0)),
    ("-x", (-1, 0, 0)),
    ("+y", (0, 1, 0)),
    ("-y", (0, -1, 0)),
    ("+z", (0, 0, 1)),
    ("-z", (0, 0, -1)),
)
CANDIDATES = (  # the probe's three mounts, then the chosen one (model.MOUNT) and its neighbours
    model.Mount(height=0.26, radius=0.0, tilt_deg=0.0),  # TriFinger-like: above the object, pointing down
    model.Mount(height=0.15, radius=0.0, tilt_deg=0.0),
    model.Mount(height=0.18, radius=0.10, tilt_deg=25.0),
    model.Mount(height=0.18, radius=0.09, tilt_deg=15.0),
    model.Mount(height=0.17, radius=0.09, tilt_deg=15.0),
    model.Mount(height=0.19, radius=0.09, tilt_deg=15.0),
    model.Mount(height=0.18, radius=0.07, tilt_deg=15.0),
    model.Mount(height=0.18, radius=0.11, tilt_deg=15.0),
    model.Mount(height=0.18, radius=0.09, tilt_deg=10.0),
    model.Mount(height=0.18, radius=0.09, tilt_deg=20.0),
)


def face_contacts(normal) -> np.ndarray:
    """(9, 3) contacts p_GC of the face with outward `normal`, on its 3 x 3 grid."""
    n = np.array(normal, dtype=float)
    axes = [e for e in np.eye(3) if abs(e @ n) < 0.5]
    return np.array([n * CUBE_SIZE / 2 + a * axes[0] + b * axes[1] for a in GRID for b in GRID])


class FingerReach:
    """One finger (at 0 deg) and the cube welded at G, with its IK."""

    def __init__(self, mount):
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        Parser(plant).AddModelsFromString(model.hand_sdf(mount, (0.0,)), "sdf")
        cube = plant.AddRigidBody(
            "cube", plant.AddModelInstance("cube"), SpatialInertia(0.094, np.zeros(3), UnitInertia.SolidCube(CUBE_SIZE))
        )
        cube_id = plant.RegisterCollisionGeometry(
            cube, RigidTransform(), Box(*[CUBE_SIZE] * 3), "cube", ProximityProperties()
        )
        plant.WeldFrames(plant.world_frame(), cube.body_frame())
        plant.Finalize()
        inspector = scene_graph.model_inspector()
        tips = [g for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName("finger0_link3"))]
        tip = [g for g in tips if inspector.GetName(g).endswith("tip_collision")]
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeBetween(GeometrySet(tip), GeometrySet(cube_id))
        )
        self.diagram = builder.Build()
        self.plant = plant
        self.tip = plant.GetFrameByName("finger0_tip")
        self.lower, self.upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
        self.starts = [(self.lower + self.upper) / 2] + list(
            np.random.default_rng(0).uniform(self.lower, self.upper, size=(STARTS - 1, 3))
        )
        self.solver = SnoptSolver()

    def reachable(self, p_GT: np.ndarray) -> bool:
        """Whether the fingertip's centre reaches p_GT with the links clear of the cube."""
        context = self.diagram.CreateDefaultContext()
        ik = InverseKinematics(self.plant, self.plant.GetMyMutableContextFromRoot(context))
        ik.AddPositionConstraint(self.tip, np.zeros(3), self.plant.world_frame(), p_GT - TOLERANCE, p_GT + TOLERANCE)
        ik.AddMinimumDistanceLowerBoundConstraint(CLEARANCE, 0.01)
        for q0 in self.starts:
            if self.solver.Solve(ik.prog(), q0).is_success():
                return True
        return False


def measure(mount) -> np.ndarray:
    """(6,) finger 0's reachable fraction of each face's grid (FACES order)."""
    reach = FingerReach(mount)
    out = []
    for _, normal in FACES:
        points = face_contacts(normal) + model.TIP_RADIUS * np.array(normal, dtype=float)
        out.append(np.mean([reach.reachable(p) for p in points]))
    return np.array(out)


def rotated_face(face: int, quarter_turns: int) -> int:
    """The FACES index of face `face` turned by quarter_turns x 90 deg about the vertical."""
    n = np.array(FACES[face][1], dtype=float)
    c, s = round(math.cos(quarter_turns * math.pi / 2)), round(math.sin(quarter_turns * math.pi / 2))
    turned = np.array([c * n[0] - s * n[1], s * n[0] + c * n[1], n[2]])
    return next(i for i, (_, m) in enumerate(FACES) if np.allclose(m, turned))


def per_finger(fraction0: np.ndarray) -> np.ndarray:
    """(4, 6): finger i's fraction of each face, from finger 0's by the quarter-turn symmetry."""
    out = np.zeros((4, 6))
    for i in range(4):
        for f in range(6):
            out[i, rotated_face(f, i)] = fraction0[f]
    return out


def report(mount, fractions: np.ndarray, seconds: float) -> str:
    """One mount's lines: per finger its fractions per face, per face the fingers that reach it."""
    names = [n for n, _ in FACES]
    lines = [
        f"mount: height {mount.height} m, radius {mount.radius} m, tilt {mount.tilt_deg} deg ({seconds:.0f} s)",
        "  finger  " + "  ".join(f"{n:>5}" for n in names),
    ]
    lines += [f"  {i:6d}  " + "  ".join(f"{v:5.2f}" for v in row) for i, row in enumerate(fractions)]
    by_face = [
        f"{n} {int(np.sum(fractions[:, f] > 0))} ({np.sum(fractions[:, f]) * 9:.0f})" for f, n in enumerate(names)
    ]
    lines.append("  fingers reaching each face (reachable contacts of 9 per finger, summed): " + ", ".join(by_face))
    lines.append(f"  reachable contacts in all: {np.sum(fractions) * 9:.0f} of {4 * 6 * 9}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only-chosen", action="store_true", help="measure only the model's mount")
    args = parser.parse_args(argv)
    for mount in (model.MOUNT,) if args.only_chosen else CANDIDATES:
        start = time.process_time()
        fractions = per_finger(measure(mount))
        print(report(mount, fractions, time.process_time() - start), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
