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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from trajectotree.geometry import ConvexPolygon, poses_box_to_world, poses_world_to_box
from trajectotree.scene.finger_clearance import ClosestFingers, closest_fingers

# The check's value type and its tolerances live with the other saved values (plan.json records both).
if TYPE_CHECKING:  # annotations only: the check itself needs numpy alone
    from trajectotree.scene.plant import FingerGeometry
from trajectotree.results import (
    CONE_TOL,
    FINGER_OVERLAP_TOL,
    FORCE_TOL,
    GAP_TOL,
    LINK_PENETRATION_TOL,
    NEWTON_EULER_TOL,
    PENETRATION_TOL,
    PhysicsCheck,
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
    away = np.where(gap > GAP_TOL, force, 0.0)
    k, i = np.unravel_index(int(np.argmax(away)), away.shape)
    worst = float(away[k, i])
    k_deep, i_deep = np.unravel_index(int(np.argmin(gap)), gap.shape)
    penetration = max(0.0, -float(gap[k_deep, i_deep]))
    if box.fingers is None:
        link_depth, k_link, i_link = float("nan"), -1, -1
        apart = ClosestFingers(float("nan"), -1, ())
    else:
        apart = closest_fingers(box.fingers, arrays["q"], box.tip_radius)
        links = link_penetrations(x, arrays["q"], box.fingers, box.shape).max(axis=2)  # (K, 4)
        k_link, i_link = np.unravel_index(int(np.argmax(links)), links.shape)
        link_depth = float(links[k_link, i_link])
        k_link, i_link = (int(k_link), int(i_link)) if link_depth > 0 else (-1, -1)
    off_surface = float(np.abs(box.shape.signed_distances(poses_world_to_box(x, a["p_W_C"]))).max())
    reasons = [] if all(np.all(np.isfinite(v)) for v in a.values()) else ["the plan arrays hold non-finite values"]
    if worst > FORCE_TOL:
        reasons.append(
            f"finger {i} pushes the box with {worst:.3g} N from {1e3 * gap[k, i]:.2f} mm away at knot {k} "
            f"(limit {FORCE_TOL} N beyond {1e3 * GAP_TOL:g} mm)"
        )
    if penetration > PENETRATION_TOL:
        reasons.append(
            f"finger {i_deep} sinks {1e3 * penetration:.2f} mm into the box at knot {k_deep} "
            f"(limit {1e3 * PENETRATION_TOL:g} mm)"
        )
    if link_depth > LINK_PENETRATION_TOL:
        reasons.append(
            f"a link of finger {i_link} overlaps the box by {1e3 * link_depth:.2f} mm at knot {k_link} "
            f"(limit {1e3 * LINK_PENETRATION_TOL:g} mm)"
        )
    if -apart.distance > FINGER_OVERLAP_TOL:
        reasons.append(
            f"fingers {apart.fingers[0]} and {apart.fingers[1]} overlap by {-1e3 * apart.distance:.2f} mm at knot "
            f"{apart.knot} (limit {1e3 * FINGER_OVERLAP_TOL:g} mm)"
        )
    if cone > CONE_TOL:
        reasons.append(f"friction cone violated by {cone:.3g} N (mu {mu:g})")
    if max(ne_force, ne_moment) > NEWTON_EULER_TOL:
        reasons.append(f"Newton-Euler residual {ne_force:.3g} N, {ne_moment:.3g} N m (limit {NEWTON_EULER_TOL:g})")
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
        penetration_m=penetration,
        link_penetration_m=link_depth,
        link_penetration_knot=k_link,
        link_penetration_finger=i_link,
        passed=not reasons,
        reason="; ".join(reasons),
        finger_distance_m=apart.distance,
        finger_distance_knot=apart.knot,
        finger_distance_fingers=apart.fingers,
    )
