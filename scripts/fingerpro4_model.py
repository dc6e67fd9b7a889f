"""Writes models/fingerpro4.sdf: four TriFinger Pro fingers around a cube held in the air.

The finger is written from its published numbers (the TriFinger Pro URDF and the robot challenge's
documentation), not read from the `robot-properties-fingers` package: that package pulls in `pin`
(Pinocchio) and `xacro` to describe one serial chain of three joints, and its meshes are STL,
which Drake rejects as collision geometry. Primitive shapes (capsules, spheres) are all the
planner's collision queries need.

`python scripts/fingerpro4_model.py` rewrites the model with the chosen mount (MOUNT);
`scripts/fingerpro4_reach.py` measures other mounts with `hand_sdf(Mount(...))`.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pydrake.math import RollPitchYaw, RotationMatrix

MODEL_PATH = Path(__file__).parents[1] / "models" / "fingerpro4.sdf"

# The TriFinger Pro finger, in its base frame Fb at joint 1 (z up, +y toward the object when mounted):
# joint offsets from the previous joint (m) and the joint axes; limits (rad); masses (kg).
JOINT_OFFSETS = ((0.0, 0.0, 0.0), (0.01685, 0.0505, 0.0), (0.05015, 0.0, -0.16))
JOINT_AXES = ((0, 1, 0), (1, 0, 0), (1, 0, 0))
JOINT_LIMITS = ((-0.33, 1.0), (0.0, 1.57), (-2.7, 0.0))
TIP_OFFSET = (0.019, 0.0, -0.16)  # m, the fingertip sphere's centre from joint 3
LINK_MASSES = (0.267, 0.272, 0.0557)  # kg, upper, middle, lower link
TIP_MASS = 0.0092  # kg, the fingertip, lumped into the lower link at the sphere's centre
TIP_RADIUS = 0.010  # m
TAU_MAX = 0.396  # N m, each joint's motor
# Collision capsules along each link's segment (m): radius, and how far short of the segment's end the
# lower link's capsule stops so that only the fingertip sphere can touch a face the tip presses on
# (0.010 + 0.020 cos(a) - 0.008 >= 2 mm for any approach angle a <= 90 deg).
LINK_RADII = (0.012, 0.012, 0.008)
LOWER_LINK_GAP = 0.020
MU = 0.7  # the fingertips' and links' friction as written (the scene sets its own)
FINGER_ANGLES_DEG = (0.0, 90.0, 180.0, 270.0)  # about the vertical, finger i at 90 i deg
COLOURS = ("0.85 0.20 0.20 1", "0.20 0.65 0.25 1", "0.20 0.40 0.85 1", "0.90 0.65 0.10 1")


class Mount(NamedTuple):
    """Where each finger's base frame Fb sits relative to the grasp point G (the cube's centre, the
    model's origin): `height` m above G, `radius` m out from the vertical axis through G, turned
    about that axis so +y of Fb points outward (as the TriFinger mounts them: joint 2 swings the
    middle link outward, joint 3 the lower link back in, the knee out and the tip in), then tilted
    `tilt_deg` about its x so the hanging finger leans toward the axis (a NamedTuple: immutable, and
    loadable from a script that is not a registered module)."""

    height: float
    radius: float
    tilt_deg: float

    def pose(self, angle_deg: float) -> tuple[np.ndarray, RotationMatrix]:
        """(p_GFb, R_GFb) of the finger at `angle_deg` about the vertical."""
        phi = math.radians(angle_deg)
        R = RotationMatrix.MakeZRotation(phi - math.pi / 2) @ RotationMatrix.MakeXRotation(-math.radians(self.tilt_deg))
        return np.array([self.radius * math.cos(phi), self.radius * math.sin(phi), self.height]), R


# The chosen mount: of those measured, one that reaches every face of a 6.5 cm cube at G by at least two
# fingers with the most reachable contacts (docs/measurements.md, "The four-finger hand in space").
MOUNT = Mount(height=0.18, radius=0.09, tilt_deg=15.0)


def _fmt(values) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


def _rod_inertia(mass: float, a: np.ndarray, b: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(p_com, I about the COM) of a solid cylinder from a to b (m)."""
    d = b - a
    length = float(np.linalg.norm(d))
    u = d / length
    axial, across = mass * radius**2 / 2, mass * (3 * radius**2 + length**2) / 12
    return (a + b) / 2, across * (np.eye(3) - np.outer(u, u)) + axial * np.outer(u, u)


def _link_inertial(index: int) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, p_com, I about the COM) in the link's frame: a uniform rod along its segment, the
    lower link with the fingertip's point mass at the sphere's centre."""
    end = np.array(JOINT_OFFSETS[index + 1] if index < 2 else TIP_OFFSET)
    mass, com, inertia = LINK_MASSES[index], *_rod_inertia(LINK_MASSES[index], np.zeros(3), end, LINK_RADII[index])
    if index == 2:
        total = mass + TIP_MASS
        c = (mass * com + TIP_MASS * end) / total

        def shift(m, p):  # parallel axis: a mass m at offset p from the new COM
            return m * (p @ p * np.eye(3) - np.outer(p, p))

        inertia = inertia + shift(mass, com - c) + shift(TIP_MASS, end - c)
        mass, com = total, c
    return mass, com, inertia


def _capsule(index: int) -> tuple[np.ndarray, RollPitchYaw, float, float]:
    """(centre, orientation, length, radius) of link `index`'s collision capsule in its frame."""
    end = np.array(JOINT_OFFSETS[index + 1] if index < 2 else TIP_OFFSET, dtype=float)
    if index == 2:
        end = end * (1 - LOWER_LINK_GAP / np.linalg.norm(end))
    R = RotationMatrix.MakeFromOneVector(end, 2)  # a capsule's axis is its frame's z
    return end / 2, RollPitchYaw(R), float(np.linalg.norm(end)), LINK_RADII[index]


def _proximity() -> str:
    return (
        f"<drake:proximity_properties><drake:mu_dynamic>{MU}</drake:mu_dynamic>"
        f"<drake:mu_static>{MU}</drake:mu_static></drake:proximity_properties>"
    )


def _link(finger: int, index: int, pose: str, colour: str) -> str:
    mass, com, I = _link_inertial(index)
    centre, rpy, length, radius = _capsule(index)
    capsule = (
        f"<pose>{_fmt(centre)} {_fmt(rpy.vector())}</pose>"
        f"<geometry><capsule><radius>{radius}</radius><length>{length:.6g}</length></capsule></geometry>"
    )
    name = f"finger{finger}_link{index + 1}"
    lines = [
        f'  <link name="{name}">',
        f"    {pose}",
        f"    <inertial><pose>{_fmt(com)} 0 0 0</pose><mass>{mass:.6g}</mass><inertia>"
        f"<ixx>{I[0, 0]:.6e}</ixx><ixy>{I[0, 1]:.6e}</ixy><ixz>{I[0, 2]:.6e}</ixz>"
        f"<iyy>{I[1, 1]:.6e}</iyy><iyz>{I[1, 2]:.6e}</iyz><izz>{I[2, 2]:.6e}</izz></inertia></inertial>",
        f'    <visual name="visual">{capsule}<material><diffuse>0.40 0.40 0.45 1</diffuse></material></visual>',
        f'    <collision name="collision">{capsule}{_proximity()}</collision>',
    ]
    if index == 2:
        sphere = (
            f"<pose>{_fmt(TIP_OFFSET)} 0 0 0</pose><geometry><sphere><radius>{TIP_RADIUS}</radius></sphere></geometry>"
        )
        lines += [
            f'    <visual name="tip_visual">{sphere}<material><diffuse>{colour}</diffuse></material></visual>',
            f'    <collision name="tip_collision">{sphere}{_proximity()}</collision>',
        ]
    return "\n".join(lines + ["  </link>"])


def _joint(finger: int, index: int) -> str:
    parent = "world" if index == 0 else f"finger{finger}_link{index}"
    lower, upper = JOINT_LIMITS[index]
    return (
        f'  <joint name="finger{finger}_joint{index + 1}" type="revolute">\n'
        f"    <parent>{parent}</parent><child>finger{finger}_link{index + 1}</child>\n"
        f"    <axis><xyz>{_fmt(JOINT_AXES[index])}</xyz><limit><lower>{lower}</lower><upper>{upper}</upper>"
        f"<effort>{TAU_MAX}</effort></limit></axis>\n"
        "  </joint>"
    )


def finger_sdf(finger: int, angle_deg: float, mount: Mount) -> str:
    """The SDF elements of finger `finger` at `angle_deg` about the vertical."""
    p, R = mount.pose(angle_deg)
    parts = [f"  <!-- finger {finger}: at {angle_deg:g} deg about the vertical -->"]
    for index in range(3):
        if index == 0:
            pose = f"<pose>{_fmt(p)} {_fmt(RollPitchYaw(R).vector())}</pose>"
        else:
            pose = f'<pose relative_to="finger{finger}_link{index}">{_fmt(JOINT_OFFSETS[index])} 0 0 0</pose>'
        parts += [_link(finger, index, pose, COLOURS[finger % len(COLOURS)]), _joint(finger, index)]
    parts.append(
        f'  <frame name="finger{finger}_tip" attached_to="finger{finger}_link3">'
        f"<pose>{_fmt(TIP_OFFSET)} 0 0 0</pose></frame>"
    )
    return "\n".join(parts)


def hand_sdf(mount: Mount = MOUNT, angles_deg=FINGER_ANGLES_DEG) -> str:
    """The hand's SDF text: one finger per angle, each at `mount`."""
    header = f"""<?xml version="1.0"?>
<!-- fingerpro4: four TriFinger Pro fingers at {", ".join(f"{a:g}" for a in angles_deg)} deg about the vertical,
     around a cube held in the air at the model's origin G (z up, gravity -z). Written by
     scripts/fingerpro4_model.py from the finger's published numbers (the TriFinger Pro URDF and the
     robot challenge's documentation), not built from the robot-properties-fingers package: that
     package needs Pinocchio (pin) and xacro to describe one chain of three joints, and its STL
     meshes are no collision geometry for Drake. Each finger, in its base frame Fb at joint 1: joint 1
     about y [-0.33, 1.0] rad; joint 2 at (0.01685, 0.0505, 0) m about x [0, 1.57]; joint 3 at
     (0.05015, 0, -0.16) about x [-2.7, 0]; the fingertip sphere (r 0.010 m, frame fingerI_tip) at
     (0.019, 0, -0.16) from joint 3. Links 0.267, 0.272, 0.0557 kg (uniform rods along their
     segments), fingertip 0.0092 kg; a 0.396 N m motor per joint (the effort limit makes Drake's
     actuator). Collision: capsules along the links (r 12, 12, 8 mm; the lower one stops 20 mm short
     of the tip's centre) and the fingertip sphere.
     Mount: Fb {mount.height:g} m above G, {mount.radius:g} m out from the vertical axis, +y outward,
     tilted {mount.tilt_deg:g} deg inward (docs/measurements.md, "The four-finger hand in space"). -->
<sdf version="1.9">
<model name="fingerpro4">
"""
    body = "\n".join(finger_sdf(i, a, mount) for i, a in enumerate(angles_deg))
    return header + body + "\n</model>\n</sdf>\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(MODEL_PATH), help="the SDF to write (default: %(default)s)")
    args = parser.parse_args(argv)
    Path(args.out).write_text(hand_sdf())
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
