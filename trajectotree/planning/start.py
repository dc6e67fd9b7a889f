"""Planning from a measured state (trajectotree.start.StartState).

A start is accepted when it is a state of the scene (a joint angle per joint of its hand, each
within the model's limits, the object's pose within the scene's bounds), the object is nearly at
rest and every fingertip touches its surface in a grasp that is in frictional form closure at
mu_plan: the search is then rooted at exactly those contacts (search.initial_arclengths) at the
start's object pose (scene.initial_pose), and the plan's first node carries the measured joint
angles, so CITO's first knot is the measured state. Anything else is refused before planning, with
a `StartRefusal` that names the finger (or joint), the value and the limit.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from trajectotree.config import INITIAL_POSE_BOUNDS, Config, ConfigError, mu_plan
from trajectotree.contact_plan import ContactPlan
from trajectotree.geometry import world_to_box
from trajectotree.scene.hand import JOINTS_PER_FINGER
from trajectotree.scene.plant import Scene
from trajectotree.search.grasp import FormClosure
from trajectotree.start import SpaceStartState, StartProblem, StartRefusal, StartState

if TYPE_CHECKING:  # the search in space is imported by the plans in space alone (a planar `plan` starts quicker)
    from trajectotree.search.space_tree import SpaceRoot

# The plan's nodes are static grasps (CITO holds every node's velocities at zero), so a start must be
# nearly at rest; a closed loop measures 0.02-0.05 m/s at nodes where contacts slide, a falling box
# 1 m/s within 0.1 s.
START_SPEED_LIMIT = 0.1  # m/s
START_SPIN_LIMIT = 1.0  # rad/s
# m, a fingertip sphere this close to the surface touches it: simulated grasps sink 0.1-0.5 mm into
# the object under their squeeze; a lifted (switching) finger is 8 mm or more away
TOUCH_DISTANCE = 2e-3


class StartRefused(ConfigError):
    """A start state that cannot be planned from (the CLI exits 2); `refusal` says why."""

    def __init__(self, refusal: StartRefusal):
        super().__init__(str(refusal))
        self.refusal = refusal


def start_contacts(scene: Scene, start: StartState) -> np.ndarray:
    """(F,) m, each finger's contact arclength: the boundary point nearest its fingertip sphere,
    which must touch the surface (StartRefused otherwise); the start's own arclengths, when given,
    must agree with it."""
    shape = scene.config.shape
    p_WF = scene.fingertip_positions(np.asarray(start.q))  # (F, 2)
    p_BF = np.array([world_to_box(start.object_pose, p) for p in p_WF])
    gaps = shape.signed_distances(p_BF) - scene.tip_radius
    for i in range(scene.num_fingers):
        if abs(gaps[i]) > TOUCH_DISTANCE:
            raise StartRefused(StartRefusal(StartProblem.FINGER_OFF, i, float(abs(gaps[i])), TOUCH_DISTANCE))
    arclengths = np.array([shape.arclength(p) for p in p_BF])
    if start.arclengths is not None:
        given = np.mod(np.asarray(start.arclengths, dtype=float), shape.perimeter)
        p_given, _ = shape.points(given)
        p_tips = shape.nearest_points(p_BF)
        for i in range(scene.num_fingers):
            off = float(np.linalg.norm(p_given[i] - p_tips[i]))
            if off > TOUCH_DISTANCE:
                raise StartRefused(StartRefusal(StartProblem.CONTACT_MISMATCH, i, off, TOUCH_DISTANCE))
        arclengths = given
    return arclengths


def check_fits_scene(scene: Scene, start: StartState) -> None:
    """StartRefused unless the start is a state of this scene: a joint angle per joint of its hand, a
    contact (when given) per finger, every joint within its limits (the model's) and the object's
    pose within the scene's bounds (config.INITIAL_POSE_BOUNDS, those of scene.initial_pose)."""
    for name, given, size in (
        ("q", start.q, scene.num_hand_joints),
        ("arclengths", start.arclengths, scene.num_fingers),
    ):
        if given is not None and len(given) != size:
            raise StartRefused(StartRefusal(StartProblem.WRONG_SIZE, value=len(given), limit=size, name=name))
    description = scene.hand_description
    lower = np.concatenate([f.q_lower for f in description.fingers])
    upper = np.concatenate([f.q_upper for f in description.fingers])
    for k, (q, low, high) in enumerate(zip(start.q, lower, upper)):
        if not low <= q <= high:  # a turn more or less may put the fingertip where it was: the limits tell
            finger, name = k // JOINTS_PER_FINGER, description.joint_names[k]
            raise StartRefused(StartRefusal(StartProblem.JOINT_LIMIT, finger, q, high, low, name, k))
    for k, (v, (low, high), name) in enumerate(zip(start.object_pose, INITIAL_POSE_BOUNDS, ("x", "y", "theta"))):
        if not low <= v <= high:
            raise StartRefused(
                StartRefusal(StartProblem.OUT_OF_BOUNDS, value=v, limit=high, lower=low, name=name, index=k)
            )


def start_config(scene: Scene, start: StartState, config: Config) -> Config:
    """The config whose search roots at the start's grasp and pose; StartRefused when the start is
    not a state of this scene (check_fits_scene), the object moves, a finger does not touch it or
    the grasp is not in closure at mu_plan."""
    check_fits_scene(scene, start)
    vx, vy, spin = start.object_velocity
    speed, spin = math.hypot(vx, vy), abs(spin)  # math's hypot: inf, not numpy's overflow warning, at 1e308 m/s
    if speed > START_SPEED_LIMIT:
        raise StartRefused(StartRefusal(StartProblem.MOVING, value=speed, limit=START_SPEED_LIMIT))
    if spin > START_SPIN_LIMIT:
        raise StartRefused(StartRefusal(StartProblem.SPINNING, value=spin, limit=START_SPIN_LIMIT))
    arclengths = start_contacts(scene, start)
    mu = mu_plan(config.scene, config.search)
    closure = FormClosure(scene.config.shape, mu, config.search.min_closure_margin)
    if not closure.check(arclengths).in_closure:
        raise StartRefused(StartRefusal(StartProblem.NOT_IN_CLOSURE, value=closure.required_mu(arclengths), limit=mu))
    scene_config = dataclasses.replace(config.scene, initial_pose=tuple(float(c) for c in start.object_pose))
    search = dataclasses.replace(
        config.search, initial_arclengths=tuple(float(s) for s in arclengths), measured_start=True
    )
    return dataclasses.replace(config, scene=scene_config, search=search)


def begin_at(plan: ContactPlan, start: StartState) -> ContactPlan:
    """The contact plan with its first node at the measured joint angles (the search's IK puts
    each fingertip exactly on its contact; the measured one may sit up to TOUCH_DISTANCE off)."""
    first = dataclasses.replace(plan.nodes[0], q=np.asarray(start.q, dtype=float))
    return dataclasses.replace(plan, nodes=(first, *plan.nodes[1:]))


# -- in space --------------------------------------------------------------------------------------
# m, how far a fingertip may be from touching the cube at a start in space: the 3D physics check counts no force
# from farther than 1 mm (issue 36), so a finger farther off would push from where the check says it cannot.
SPACE_TOUCH_DISTANCE = 1e-3
REQUIRED_MU_STEPS = 20  # bisections of the friction a refused grasp needs: MAX_MU / 2^20, under 1e-5


def check_fits_space_scene(scene, start: SpaceStartState) -> None:
    """StartRefused unless the start is a state of the hand in space `scene` (scene.spatial.SpaceScene): a joint
    angle per joint, a contact (when given) per finger, every joint within the model's limits."""
    joints = sum(len(f.q_lower) for f in scene.fingers)
    for name, given, size in (("q", start.q, joints), ("contacts", start.contacts, scene.num_fingers)):
        if given is not None and len(given) != size:
            raise StartRefused(StartRefusal(StartProblem.WRONG_SIZE, value=len(given), limit=size, name=name))
    names = [n for f in scene.hand_file.fingers for n in f.joints]
    lower = np.concatenate([f.q_lower for f in scene.fingers])
    upper = np.concatenate([f.q_upper for f in scene.fingers])
    per_finger = len(scene.fingers[0].q_lower)
    for k, (q, low, high) in enumerate(zip(start.q, lower, upper)):
        if not low <= q <= high:
            raise StartRefused(StartRefusal(StartProblem.JOINT_LIMIT, k // per_finger, q, high, low, names[k], k))


def space_face_contacts(scene, start: SpaceStartState) -> tuple[np.ndarray, tuple[int, ...]]:
    """((F, 3) m, faces): each fingertip's contact with the cube in B and its face (geometry.BOX_FACE_NORMALS order):
    the face its sphere's centre is most outside of (least inside), the contact the centre's projection onto it
    clipped to the face; StartRefused (FINGER_OFF) when a centre is over SPACE_TOUCH_DISTANCE from where it would
    touch that face there (off the face, sunk into it or beyond its edge)."""
    from trajectotree.search.spatial_reach import box_transform

    X_WB = box_transform(start.object_pose)
    R, p = X_WB.rotation().matrix(), X_WB.translation()
    half, r = scene.object.half, scene.tip_radius
    q = np.asarray(start.q, dtype=float).reshape(scene.num_fingers, -1)
    p_BC, faces = [], []
    for i, finger in enumerate(scene.fingers):
        p_BF = R.T @ (finger.fingertip(q[i]) - p)
        axis = int(np.argmax(np.abs(p_BF) - half))
        sign = 1.0 if p_BF[axis] >= 0.0 else -1.0
        contact = np.clip(p_BF, -half, half)
        contact[axis] = sign * half[axis]
        n_B = np.zeros(3)
        n_B[axis] = sign
        off = float(np.linalg.norm(p_BF - (contact + r * n_B)))
        if off > SPACE_TOUCH_DISTANCE:
            raise StartRefused(StartRefusal(StartProblem.FINGER_OFF, i, off, SPACE_TOUCH_DISTANCE))
        p_BC.append(contact)
        faces.append(2 * axis + (sign < 0.0))
    return np.array(p_BC), tuple(faces)


def space_start_contacts(scene, start: SpaceStartState) -> tuple[np.ndarray, tuple[int, ...]]:
    """space_face_contacts, or the start's own contacts when given: each within SPACE_TOUCH_DISTANCE of its
    fingertip's (CONTACT_MISMATCH otherwise), put on that fingertip's face."""
    p_BC, faces = space_face_contacts(scene, start)
    if start.contacts is None:
        return p_BC, faces
    given = np.array(start.contacts, dtype=float)
    for i, face in enumerate(faces):
        off = float(np.linalg.norm(given[i] - p_BC[i]))
        if off > SPACE_TOUCH_DISTANCE:
            raise StartRefused(StartRefusal(StartProblem.CONTACT_MISMATCH, i, off, SPACE_TOUCH_DISTANCE))
        given[i, face // 2] = p_BC[i, face // 2]  # on the face's plane, where the fingertip's contact is
    return given, faces


def space_required_mu(p_BC: np.ndarray, faces: tuple[int, ...], half, num_edges: int) -> float:
    """The least friction (to MAX_MU / 2^REQUIRED_MU_STEPS) at which the contacts are in 6-D closure (inf: none
    up to MAX_MU)."""
    from trajectotree.config import MAX_MU
    from trajectotree.geometry import BOX_FACE_NORMALS
    from trajectotree.search.grasp import SpatialClosure

    n_B = BOX_FACE_NORMALS[list(faces)]

    def closed(mu: float) -> bool:
        return SpatialClosure(mu, half_size=float(max(half)), num_edges=num_edges).check(p_BC, n_B).in_closure

    if not closed(MAX_MU):
        return math.inf
    low, high = 0.0, MAX_MU
    for _ in range(REQUIRED_MU_STEPS):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if closed(mid) else (mid, high)
    return high


def space_start_root(scene, start: SpaceStartState, config: Config) -> SpaceRoot:
    """The measured grasp the search in space roots at (search.space_tree.SpaceRoot); StartRefused when the start is not
    a state of this scene (check_fits_space_scene), the cube moves or turns, a fingertip does not touch it (within
    SPACE_TOUCH_DISTANCE) or the four contacts are not in 6-D closure at mu_plan."""
    from trajectotree.search.space_tree import PYRAMID_EDGES, SpaceRoot

    check_fits_space_scene(scene, start)
    spin, speed = (float(np.linalg.norm(start.object_velocity[k : k + 3])) for k in (0, 3))
    if speed > START_SPEED_LIMIT:
        raise StartRefused(StartRefusal(StartProblem.MOVING, value=speed, limit=START_SPEED_LIMIT))
    if spin > START_SPIN_LIMIT:
        raise StartRefused(StartRefusal(StartProblem.SPINNING, value=spin, limit=START_SPIN_LIMIT))
    p_BC, faces = space_start_contacts(scene, start)
    mu = mu_plan(config.scene, config.search)
    needed = space_required_mu(p_BC, faces, scene.object.half, PYRAMID_EDGES)
    if needed > mu:
        raise StartRefused(StartRefusal(StartProblem.NOT_IN_CLOSURE, value=needed, limit=mu))
    q = np.asarray(start.q, dtype=float).reshape(scene.num_fingers, -1)
    return SpaceRoot(pose=np.asarray(start.object_pose, dtype=float), q=q, p_BC=p_BC, faces=faces)
