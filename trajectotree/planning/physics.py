"""The physics of a plan checked from its plan.npz arrays alone (pure numpy).

Anyone holding plan.npz can recompute these numbers (its arrays: README, "Trajectory optimization"):
  - newton_euler: the box's Newton-Euler residual under the trapezoidal rule the plan
    was made with, m (v_{k+1} - v_k) / dt - (F_k + F_{k+1}) / 2 with F = sum f_W + m g
    (translation, N), and the same for the rotation with the moments of f_W applied at
    p_W_C about the box centre (N m);
  - friction_cone: max(|lambda_t| - mu lambda_n, -lambda_n) (N), with mu the friction
    the plan was made with (mu_plan = search.friction_safety * scene.mu);
  - force at a distance: the largest force |f_W| of a fingertip whose sphere is more than
    GAP_TOL from the box (N), where it is and how far off;
  - contact_point_off_surface: how far any p_W_C lies from the box boundary (m);
  - penetration: how deep any fingertip sphere sinks into the box (m);
  - link_penetration: how deep any finger link's collision box overlaps the box (m; the least
    translation that separates them), given the hand's links (ObjectModel.fingers);
  - finger_distance: the least signed distance between two fingers' collision shapes (link boxes
    and fingertip spheres; negative: how deep they overlap) at any knot, given the hand's links
    (trajectotree.scene.finger_clearance, exact in the plane).
A plan passes when no fingertip more than GAP_TOL off the box carries more than
FORCE_TOL, none sinks deeper than PENETRATION_TOL, no link overlaps it deeper than
LINK_PENETRATION_TOL and no two fingers overlap deeper than FINGER_OVERLAP_TOL (where the
links are given), the cones hold to CONE_TOL and
Newton-Euler to NEWTON_EULER_TOL.

In space (check_space_physics, a plan of a hand in space: results.SpaceTrajectory's arrays and the
object that plan.json names) the same rules in 3D: Newton-Euler under plan.json's integration rule
(results.SPACE_INTEGRATION: trapezoidal, the rotation in angular momentum L = R I_B R^T w), the poses
against that rule's kinematics, each force in its cone (|f_t| <= mu f_n about the normal of the face
its contact lies on), no force from a fingertip sphere or contact point more than SPACE_GAP_TOL (1 mm)
off the box, no sphere sunk nor link capsule inside it more than 1 mm, and no two fingers' collision shapes
(their link capsules, p_W_links, and fingertip spheres, p_W_tip) inside each other more than
FINGER_OVERLAP_TOL (space_finger_distance: the capsules' exact distances at the knots).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from trajectotree.geometry import (
    ConvexPolygon,
    box_face_normals,
    box_signed_distances,
    capsule_distances,
    poses_box_to_world,
    poses_world_to_box,
    quaternion_matrices,
    rotation_angles,
    segment_box_distances,
    so3_exp,
)
from trajectotree.scene.finger_clearance import ClosestFingers, closest_fingers

# The check's value type and its tolerances live with the other saved values (plan.json records both).
if TYPE_CHECKING:  # annotations only: the check itself needs numpy alone
    from trajectotree.scene.plant import FingerGeometry
from trajectotree.results import (
    CONE_TOL,
    FINGER_OVERLAP_TOL,
    FORCE_TOL,
    GAP_TOL,
    KINEMATICS_TOL,
    LINK_PENETRATION_TOL,
    NEWTON_EULER_TOL,
    PENETRATION_TOL,
    SPACE_GAP_TOL,
    SPACE_TRAJECTORY_ARRAYS,
    PhysicsCheck,
    SpacePhysicsCheck,
)


@dataclass(frozen=True)
class ObjectModel:
    """What the check needs to know about the object and the fingertips."""

    mass: float  # kg
    shape: ConvexPolygon  # the outline in B
    gravity: float  # m/s^2, magnitude, along -y in W
    tip_radius: float  # m, fingertip sphere radius
    fingers: tuple[FingerGeometry, ...] | None = None  # the hand's kinematics and link boxes (None: links unchecked)
    moment: float | None = None  # kg m^2, I_zz about the centroid (SceneConfig.inertia_zz); None: a uniform plate's

    @property
    def inertia(self) -> float:
        """kg m^2, about the centroid: `moment`, else a uniform plate's."""
        return self.shape.inertia(self.mass) if self.moment is None else self.moment

    @staticmethod
    def from_scene(scene) -> ObjectModel:
        c = scene.config
        return ObjectModel(
            mass=c.box_mass,
            shape=c.shape,
            gravity=c.gravity,
            tip_radius=scene.tip_radius,
            fingers=scene.fingers,
            moment=c.inertia_zz(),  # the scene's rule: its object_inertia, else the plate's
        )


def link_penetrations(x, q, fingers, shape: ConvexPolygon) -> np.ndarray:
    """(K, F, 2) m: how deep each finger's link 1 and link 2 collision boxes overlap the object
    at object poses x (K, 3) and joint angles q (K, 2F, finger-major); 0 for a link without a box
    (it passes through the object in simulation too)."""
    depths = []
    for i, finger in enumerate(fingers):
        q_i = np.asarray(q, dtype=float)[:, 2 * i : 2 * i + 2]
        a1, a12 = finger.angles(q_i)
        frames = ((np.broadcast_to(finger.p_W_base, (len(q_i), 2)), a1), (finger.elbow(q_i), a12))
        depths.append(
            [
                np.zeros(len(q_i))
                if box is None
                else shape.penetration_depths(poses_world_to_box(x, box.corners(p_WJ, angle_WJ)))
                for box, (p_WJ, angle_WJ) in zip(finger.link_boxes, frames)
            ]
        )
    return np.moveaxis(np.array(depths), -1, 0)


def contact_points(x, p_W_tip, pinned, p_BC_planned, shape: ConvexPolygon) -> np.ndarray:
    """p_W_C (K, 4, 2), where each finger's force acts on the object: the planned contact
    point p_BC_planned (K, 4, 2, in B) where pinned (K, 4), else the boundary point
    closest to the fingertip centre."""
    x = np.asarray(x, dtype=float)
    nearest = shape.nearest_points(poses_world_to_box(x, np.asarray(p_W_tip, dtype=float)))
    p_BC = np.where(np.asarray(pinned, dtype=bool)[..., None], p_BC_planned, nearest)
    return poses_box_to_world(x, p_BC)


def check_physics(arrays, box: ObjectModel, mu: float) -> PhysicsCheck:
    """The check of a plan's arrays (a mapping with the plan.npz names t, x, xdot,
    lambda_n, lambda_t, f_W, p_W_tip, p_W_C, and q where box.fingers is given) against `box`
    and friction `mu`."""
    a = {
        name: np.asarray(arrays[name], dtype=float)
        for name in ("t", "x", "xdot", "lambda_n", "lambda_t", "f_W", "p_W_tip", "p_W_C")
    }
    x, f = a["x"], a["f_W"]
    dt = np.diff(a["t"])[:, None]
    weight = np.array([0.0, -box.mass * box.gravity])
    arm = a["p_W_C"] - x[:, None, :2]
    moment = np.sum(arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0], axis=1)
    wrench = np.concatenate([f.sum(1) + weight, moment[:, None]], axis=1)
    residual = np.array([box.mass, box.mass, box.inertia]) * np.diff(a["xdot"], axis=0) / dt - 0.5 * (
        wrench[1:] + wrench[:-1]
    )
    ne_force, ne_moment = float(np.abs(residual[:, :2]).max()), float(np.abs(residual[:, 2]).max())
    ln, lt = a["lambda_n"], a["lambda_t"]
    cone = float(np.maximum(np.abs(lt) - mu * ln, -ln).max())
    gap = box.shape.signed_distances(poses_world_to_box(x, a["p_W_tip"])) - box.tip_radius  # (K, 4)
    force = np.linalg.norm(f, axis=-1)
    away = _Largest.of(np.where(gap > GAP_TOL, force, 0.0))
    k, i, worst = away.knot, away.finger, away.value
    deep = _Largest.of(-gap)
    if box.fingers is None:
        link = _Largest(float("nan"), -1, -1)
        apart = ClosestFingers(float("nan"), -1, ())
    else:
        apart = closest_fingers(box.fingers, arrays["q"], box.tip_radius)
        link = _Largest.of(link_penetrations(x, arrays["q"], box.fingers, box.shape).max(axis=2)).located()
    off_surface = float(np.abs(box.shape.signed_distances(poses_world_to_box(x, a["p_W_C"]))).max())
    reasons = [
        *_non_finite_reason(a),
        *_force_reason(away, float(gap[k, i]), GAP_TOL),
        *_penetration_reason(deep),
        *_link_reason(link, "overlaps the box by {:.2f} mm"),
    ]
    reasons += [*_finger_reason(apart), *_cone_reason(cone, mu), *_newton_euler_reason(ne_force, ne_moment)]
    return PhysicsCheck(
        newton_euler_force_N=ne_force,
        newton_euler_moment_Nm=ne_moment,
        friction_cone_N=cone,
        mu=float(mu),
        force_at_distance_N=worst,
        force_at_distance_knot=int(k) if worst > 0 else -1,
        force_at_distance_finger=int(i) if worst > 0 else -1,
        force_at_distance_gap_m=float(gap[k, i]) if worst > 0 else 0.0,
        contact_point_off_surface_m=off_surface,
        penetration_m=max(0.0, deep.value),
        link_penetration_m=link.value,
        link_penetration_knot=link.knot,
        link_penetration_finger=link.finger,
        passed=not reasons,
        reason="; ".join(reasons),
        finger_distance_m=apart.distance,
        finger_distance_knot=apart.knot,
        finger_distance_fingers=apart.fingers,
    )


# -- in space ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpaceObjectModel:
    """What the check in space needs: the object (plan.json "object") and the hand's radii."""

    size: tuple[float, float, float]  # m, the box's edges along B's x, y, z
    mass: float  # kg
    inertia: np.ndarray  # (3, 3) kg m^2, about the centre, in B
    gravity: float  # m/s^2, along -z in W
    tip_radius: float  # m
    link_radii: tuple[float, ...]  # m, each link's capsule radius, the order of p_W_links' third axis

    @property
    def half(self) -> np.ndarray:
        return np.asarray(self.size, dtype=float) / 2

    def to_json(self) -> dict:
        return {
            "size": [float(v) for v in self.size],
            "mass": float(self.mass),
            "inertia": np.asarray(self.inertia, dtype=float).tolist(),
            "gravity": float(self.gravity),
            "tip_radius": float(self.tip_radius),
            "link_radii": [float(r) for r in self.link_radii],
        }

    @staticmethod
    def from_json(data: dict) -> SpaceObjectModel:
        return SpaceObjectModel(
            size=tuple(float(v) for v in data["size"]),
            mass=float(data["mass"]),
            inertia=np.asarray(data["inertia"], dtype=float),
            gravity=float(data["gravity"]),
            tip_radius=float(data["tip_radius"]),
            link_radii=tuple(float(r) for r in data["link_radii"]),
        )


def space_newton_euler(a, box: SpaceObjectModel) -> tuple[np.ndarray, np.ndarray]:
    """((K - 1, 3) N, (K - 1, 3) N m): the translational and rotational residuals of the rule between
    consecutive knots of the arrays `a` (results.SPACE_INTEGRATION)."""
    R = quaternion_matrices(a["x"][:, :4])
    p, w, v, f = a["x"][:, 4:], a["v"][:, :3], a["v"][:, 3:], a["f_W"]
    h = np.diff(a["t"])[:, None]
    force = f.sum(axis=1) + np.array([0.0, 0.0, -box.mass * box.gravity])
    moment = np.cross(a["p_W_C"] - p[:, None, :], f).sum(axis=1)
    momentum = np.einsum("kij,jl,kml,km->ki", R, box.inertia, R, w)  # R I_B R^T w
    translation = box.mass * np.diff(v, axis=0) - 0.5 * h * (force[1:] + force[:-1])
    rotation = np.diff(momentum, axis=0) - 0.5 * h * (moment[1:] + moment[:-1])
    return translation / h, rotation / h


def space_kinematics(a) -> tuple[float, float]:
    """(rad, m): how far the poses stray from the rule's R[k+1] = exp([h w_mid]x) R[k], p[k+1] = p[k] + h v_mid."""
    R = quaternion_matrices(a["x"][:, :4])
    h = np.diff(a["t"])[:, None]
    w_mid, v_mid = 0.5 * (a["v"][1:] + a["v"][:-1])[:, :3], 0.5 * (a["v"][1:] + a["v"][:-1])[:, 3:]
    predicted = so3_exp(h * w_mid) @ R[:-1]
    angle = rotation_angles(np.swapaxes(predicted, -1, -2) @ R[1:])
    offset = np.linalg.norm(np.diff(a["x"][:, 4:], axis=0) - h * v_mid, axis=-1)
    return float(angle.max(initial=0.0)), float(offset.max(initial=0.0))


def check_space_arrays(arrays) -> dict[str, np.ndarray]:
    """The plan in space's arrays as floats, their shapes checked against each other: K knots, F
    fingers, n joints each; ValueError naming the array, its shape and the shape expected."""
    a = {name: np.asarray(arrays[name], dtype=float) for name in SPACE_TRAJECTORY_ARRAYS}
    K = a["t"].shape[0] if a["t"].ndim == 1 else -1
    F = a["f_W"].shape[1] if a["f_W"].ndim == 3 else -1
    L = a["p_W_links"].shape[2] if a["p_W_links"].ndim == 5 else -1
    expected = {  # name: the shape, each axis (its size, its name in the message)
        "t": (("K", K),),
        "x": (("K", K), ("7", 7)),
        "v": (("K", K), ("6", 6)),
        "q": (("K", K), ("n", a["q"].shape[-1])),
        "tau": (("K", K), ("n", a["q"].shape[-1])),
        "f_W": (("K", K), ("F", F), ("3", 3)),
        "p_W_C": (("K", K), ("F", F), ("3", 3)),
        "p_W_tip": (("K", K), ("F", F), ("3", 3)),
        "p_W_links": (("K", K), ("F", F), ("L", L), ("2", 2), ("3", 3)),
    }
    for name, axes in expected.items():
        if a[name].shape != tuple(size for _, size in axes) or K < 2 or F < 1:
            want = "x".join(label for label, _ in axes)
            raise ValueError(
                f"plan.npz {name} has shape {a[name].shape}, expected ({want}) with K = {K} >= 2 knots, F = {F} fingers"
            )
    if a["q"].shape[1] % F:
        raise ValueError(f"plan.npz q has {a['q'].shape[1]} joints, not a multiple of its {F} fingers")
    return a


def space_finger_distance(a, box: SpaceObjectModel) -> ClosestFingers:
    """The closest two fingers come at the knots of the arrays `a`: the least signed distance between one's
    parts (link capsules p_W_links (K, F, L, 2, 3) of radii box.link_radii, fingertip sphere p_W_tip (K, F, 3)
    of radius box.tip_radius) and another's, with its knot and the two fingers."""
    K, F = a["p_W_tip"].shape[:2]
    if F < 2:
        return ClosestFingers(float("inf"), -1, ())
    ends = np.concatenate([a["p_W_links"], np.repeat(a["p_W_tip"][:, :, None, None, :], 2, axis=3)], axis=2)
    radii = np.r_[box.link_radii, box.tip_radius]
    i, j = np.triu_indices(F, 1)
    A, B = ends[:, i, :, None], ends[:, j, None, :]  # (K, pairs, P, P, 2, 3) by broadcasting
    gaps = capsule_distances(A[..., 0, :], A[..., 1, :], radii[:, None], B[..., 0, :], B[..., 1, :], radii[None, :])
    least = gaps.reshape(K, len(i), -1).min(axis=-1)  # (K, pairs)
    k, pair = np.unravel_index(int(np.argmin(least)), least.shape)
    return ClosestFingers(float(least[k, pair]), int(k), (int(i[pair]), int(j[pair])))


def check_space_physics(arrays, box: SpaceObjectModel, mu: float) -> SpacePhysicsCheck:
    """The check of a plan in space's arrays (plan.npz: results.SPACE_TRAJECTORY_ARRAYS, shapes checked by
    check_space_arrays) against the object `box` and friction `mu`."""
    a = check_space_arrays(arrays)
    translation, rotation = space_newton_euler(a, box)
    ne_force, ne_moment = float(np.abs(translation).max()), float(np.abs(rotation).max())
    angle_off, position_off = space_kinematics(a)
    R = quaternion_matrices(a["x"][:, :4])
    p = a["x"][:, 4:]

    def in_B(p_W):  # points (K, ..., 3) in W to B
        flat = (p_W.reshape(len(p), -1, 3) - p[:, None, :]) @ R
        return flat.reshape(p_W.shape)

    p_BC = in_B(a["p_W_C"])
    n_W = np.einsum("kij,kfj->kfi", R, box_face_normals(box.half, p_BC))
    f = a["f_W"]
    f_n = -np.sum(f * n_W, axis=-1)
    f_t = np.linalg.norm(f + f_n[..., None] * n_W, axis=-1)
    cone = float(np.maximum(f_t - mu * f_n, -f_n).max())
    force = np.linalg.norm(f, axis=-1)
    gap = box_signed_distances(box.half, in_B(a["p_W_tip"])) - box.tip_radius  # (K, F)
    off = np.abs(box_signed_distances(box.half, p_BC))
    away = _Largest.of(np.where((gap > SPACE_GAP_TOL) | (off > SPACE_GAP_TOL), force, 0.0))
    k, i, worst = away.knot, away.finger, away.value
    deep = _Largest.of(-gap)
    ends = in_B(a["p_W_links"])
    depth = np.asarray(box.link_radii) - segment_box_distances(box.half, ends[..., 0, :], ends[..., 1, :])
    link = _Largest.of(np.maximum(depth, 0.0).max(axis=2)).located()
    apart = space_finger_distance(a, box)
    reasons = [
        *_non_finite_reason(a),
        *_force_reason(away, float(max(gap[k, i], off[k, i])), SPACE_GAP_TOL),
        *_penetration_reason(deep),
        *_link_reason(link, "is {:.2f} mm inside the box"),
        *_finger_reason(apart),
        *_cone_reason(cone, mu),
        *_newton_euler_reason(ne_force, ne_moment),
    ]
    if max(angle_off, position_off) > KINEMATICS_TOL:
        reasons.append(
            f"the poses stray {angle_off:.3g} rad and {position_off:.3g} m from the integration rule "
            f"(limit {KINEMATICS_TOL:g})"
        )
    return SpacePhysicsCheck(
        newton_euler_force_N=ne_force,
        newton_euler_moment_Nm=ne_moment,
        friction_cone_N=cone,
        mu=float(mu),
        force_at_distance_N=worst,
        force_at_distance_knot=int(k) if worst > 0 else -1,
        force_at_distance_finger=int(i) if worst > 0 else -1,
        force_at_distance_gap_m=float(max(gap[k, i], off[k, i])) if worst > 0 else 0.0,
        contact_point_off_surface_m=float(off.max()),
        penetration_m=max(0.0, deep.value),
        link_penetration_m=link.value,
        link_penetration_knot=link.knot,
        link_penetration_finger=link.finger,
        passed=not reasons,
        reason="; ".join(reasons),
        kinematics_rad=angle_off,
        kinematics_m=position_off,
        finger_distance_m=apart.distance,
        finger_distance_knot=apart.knot,
        finger_distance_fingers=apart.fingers,
    )


# -- the reasons a check fails, worded alike in the plane and in space ------------------------------
@dataclass(frozen=True)
class _Largest:
    """The largest of a (K, F) array of per-knot, per-finger values, with its knot and finger."""

    value: float
    knot: int
    finger: int

    @staticmethod
    def of(values: np.ndarray) -> _Largest:
        k, i = np.unravel_index(int(np.argmax(values)), values.shape)
        return _Largest(float(values[k, i]), int(k), int(i))

    def located(self) -> _Largest:
        """This, its knot and finger -1 where the value is not positive (nothing found)."""
        return self if self.value > 0 else _Largest(self.value, -1, -1)


def _non_finite_reason(a: dict[str, np.ndarray]) -> list[str]:
    return [] if all(np.all(np.isfinite(v)) for v in a.values()) else ["the plan arrays hold non-finite values"]


def _force_reason(away: _Largest, distance: float, gap_tol: float) -> list[str]:
    """The largest force of a fingertip off the box, `distance` m off, over FORCE_TOL."""
    if not away.value > FORCE_TOL:
        return []
    return [
        f"finger {away.finger} pushes the box with {away.value:.3g} N from {1e3 * distance:.2f} mm away at "
        f"knot {away.knot} (limit {FORCE_TOL} N beyond {1e3 * gap_tol:g} mm)"
    ]


def _penetration_reason(deep: _Largest) -> list[str]:
    """The deepest fingertip (`deep`: the largest negated gap) sunk beyond PENETRATION_TOL."""
    if not deep.value > PENETRATION_TOL:
        return []
    return [
        f"finger {deep.finger} sinks {1e3 * deep.value:.2f} mm into the box at knot {deep.knot} "
        f"(limit {1e3 * PENETRATION_TOL:g} mm)"
    ]


def _link_reason(link: _Largest, how: str) -> list[str]:
    """The deepest link beyond LINK_PENETRATION_TOL; `how` words its depth in mm ({} its place)."""
    if not link.value > LINK_PENETRATION_TOL:
        return []
    return [
        f"a link of finger {link.finger} {how.format(1e3 * link.value)} at knot {link.knot} "
        f"(limit {1e3 * LINK_PENETRATION_TOL:g} mm)"
    ]


def _finger_reason(apart: ClosestFingers) -> list[str]:
    """Two fingers overlapping deeper than FINGER_OVERLAP_TOL (`apart`: the closest two, NaN: unchecked)."""
    if not -apart.distance > FINGER_OVERLAP_TOL:
        return []
    return [
        f"fingers {apart.fingers[0]} and {apart.fingers[1]} overlap by {-1e3 * apart.distance:.2f} mm at knot "
        f"{apart.knot} (limit {1e3 * FINGER_OVERLAP_TOL:g} mm)"
    ]


def _cone_reason(cone: float, mu: float) -> list[str]:
    return [f"friction cone violated by {cone:.3g} N (mu {mu:g})"] if cone > CONE_TOL else []


def _newton_euler_reason(force: float, moment: float) -> list[str]:
    if not max(force, moment) > NEWTON_EULER_TOL:
        return []
    return [f"Newton-Euler residual {force:.3g} N, {moment:.3g} N m (limit {NEWTON_EULER_TOL:g})"]
