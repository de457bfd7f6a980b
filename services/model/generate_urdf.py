"""Generate the ``hrp2_like`` URDF from the published HRP-2 facts (CONVENTIONS §5).

The model is built from primitives only (boxes, cylinders, spheres) so that pinocchio, coal and
pybullet all load it without meshes. Every number that defines the robot is in this file; the
URDF under ``services/model/data/hrp2_like.urdf`` is its output and is never edited by hand
(``scripts/gen_hrp2_urdf.py --check`` and ``tests/test_model.py`` verify it is up to date).

Facts used (HRP-2, Kaneko et al. 2004 and the OpenHRP model):

- 1.54 m tall with straight legs, 58 kg, 30 actuated DoF with the HRP-2 joint names:
  ``RLEG_JOINT0..5`` / ``LLEG_JOINT0..5`` (hip yaw, roll, pitch; knee; ankle pitch, roll),
  ``CHEST_JOINT0..1`` (yaw, pitch), ``HEAD_JOINT0..1`` (pan, tilt), ``RARM_JOINT0..6`` /
  ``LARM_JOINT0..6`` (shoulder pitch, roll, yaw; elbow; wrist yaw, pitch; gripper).
- Thigh 0.30 m, shank 0.30 m, ankle to sole 0.105 m, hips at y = +-0.06 m with a 0.035 m lateral
  thigh offset (ankles at y = +-0.095 m), sole 0.24 x 0.14 m.
- Half-sitting hip pitch -0.4538, knee 0.8727, ankle pitch -0.4189 rad puts the waist (the hip
  pitch axes) at 0.3 cos(0.4538) + 0.3 cos(0.4189) + 0.105 = 0.6487 m.
- Two stereo pairs in the head: 0.144 m baseline (lower, "wide") and 0.058 m (upper, "narrow").

Joint position ranges follow the HRP-2 model; velocity and effort limits, link masses and
inertias are plausible values for a robot of this class (HRP-2's exact figures are not published),
scaled so that the total mass is exactly 58 kg.

The gripper is one moving finger sliding (prismatic, [m]) towards a fixed finger: the open gap is
0.13 m (holds a 0.10 m ball) and the closed gap 0.01 m (holds a 0.024 m bar). The grasp frame
is at the centre of the open gap, between the fingertips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_URDF_PATH = DATA_DIR / "hrp2_like.urdf"

TOTAL_MASS_KG = 58.0
FRAME_LINK_MASS_KG = 0.001  # explicit small mass on frame-only links (pybullet would give them 1 kg)

# Leg geometry [m].
HIP_Y_M = 0.06
THIGH_LATERAL_OFFSET_M = 0.035
THIGH_M = 0.30
SHANK_M = 0.30
ANKLE_TO_SOLE_M = 0.105
SOLE_LENGTH_M = 0.24
SOLE_WIDTH_M = 0.14
FOOT_THICKNESS_M = 0.035

# Upper body geometry [m].
CHEST_JOINT_XYZ = (0.032, 0.0, 0.3507)
HEAD_JOINT_XYZ = (-0.007, 0.0, 0.2973)
SHOULDER_XYZ = (0.008, 0.25, 0.1915)  # left shoulder in the chest frame; right is mirrored
UPPER_ARM_M = 0.25
FOREARM_M = 0.25
WRIST_TO_GRASP_M = 0.14
HEAD_TOP_ABOVE_HEAD_JOINT_M = 0.187  # makes the straight-legged height 1.540 m

# Gripper [m]: fixed finger on the +y side (right hand; mirrored for the left hand), moving finger
# sliding along +y. q = 0 is open (gap 0.13 m), q = 0.12 is closed (gap 0.01 m).
FINGER_TOP_Z_M = -0.085  # in the wrist (hand) frame
FINGER_LENGTH_M = 0.10
FINGER_THICKNESS_M = 0.015
FINGER_DEPTH_M = 0.035
GRIPPER_OPEN_GAP_M = 0.13
GRIPPER_TRAVEL_M = 0.12

# Cameras, in the head (HEAD_LINK1) frame [m].
CAMERA_X_M = 0.115
WIDE_BASELINE_M = 0.144
WIDE_Z_M = 0.06
NARROW_BASELINE_M = 0.058
NARROW_Z_M = 0.12

# Optical frame (z forward, x right, y down) relative to a body-convention frame (x forward, y left,
# z up): R = Rz(-pi/2) Ry(0) Rx(-pi/2) in URDF fixed-axis rpy.
OPTICAL_RPY = (-math.pi / 2, 0.0, -math.pi / 2)

DEG = math.pi / 180.0

# Colours (r, g, b, a).
COLOURS = {
    "white": (0.92, 0.92, 0.92, 1.0),
    "silver": (0.62, 0.64, 0.68, 1.0),
    "blue": (0.16, 0.30, 0.62, 1.0),
    "dark": (0.15, 0.15, 0.17, 1.0),
    "black": (0.05, 0.05, 0.05, 1.0),
    "red": (0.80, 0.10, 0.10, 1.0),
}


@dataclass(frozen=True)
class Shape:
    """A collision/visual primitive in its link frame. ``size``: box (x, y, z), cylinder (radius,
    length) along z, sphere (radius,) [m]."""

    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    colour: str = "white"
    collide: bool = True  # False: visual only (joint housings inside their neighbours' volumes)


@dataclass(frozen=True)
class Link:
    """A link: mass [kg], centre of mass [m] and inertia [kg m^2] about the CoM, shapes."""

    name: str
    mass_kg: float
    com_xyz: tuple[float, float, float]
    inertia: tuple[float, float, float]  # principal moments ixx, iyy, izz (axes of the link frame)
    shapes: tuple[Shape, ...] = ()


@dataclass(frozen=True)
class Joint:
    """A joint from ``parent`` to ``child`` at ``xyz``/``rpy`` [m, rad]; limits in rad or m."""

    name: str
    kind: str  # revolute | prismatic | fixed
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    lower: float = 0.0
    upper: float = 0.0
    velocity: float = 0.0
    effort: float = 0.0


@dataclass
class _Builder:
    links: list[Link] = field(default_factory=list)
    joints: list[Joint] = field(default_factory=list)

    def link(self, link: Link) -> None:
        self.links.append(link)

    def joint(self, joint: Joint) -> None:
        self.joints.append(joint)

    def chain(self, prefix: str, parent: str, specs: list, links: list[Link]) -> str:
        """Add a serial chain of revolute joints ``{prefix}_JOINT{suffix}``, one per link, from ``parent``.

        ``specs`` rows are ``(suffix, axis, xyz [m] in the parent's frame, (lower, upper) [deg],
        velocity [rad/s], effort [N m])``. Returns the name of the chain's last link.
        """
        for (suffix, axis, xyz, (lo, hi), vel, eff), link in zip(specs, links, strict=True):
            self.link(link)
            self.joint(
                Joint(
                    f"{prefix}_JOINT{suffix}",
                    "revolute",
                    parent,
                    link.name,
                    xyz,
                    axis=axis,
                    lower=lo * DEG,
                    upper=hi * DEG,
                    velocity=vel,
                    effort=eff,
                )
            )
            parent = link.name
        return parent


def _box_inertia(mass_kg: float, size: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, z = size
    return (
        mass_kg * (y * y + z * z) / 12.0,
        mass_kg * (x * x + z * z) / 12.0,
        mass_kg * (x * x + y * y) / 12.0,
    )


def _cylinder_inertia(mass_kg: float, radius_m: float, length_m: float) -> tuple[float, float, float]:
    i_xy = mass_kg * (3.0 * radius_m**2 + length_m**2) / 12.0
    return (i_xy, i_xy, mass_kg * radius_m**2 / 2.0)


def _frame_link(name: str) -> Link:
    i = 1e-7
    return Link(name, FRAME_LINK_MASS_KG, (0.0, 0.0, 0.0), (i, i, i))


def _mirror(xyz: tuple[float, float, float], sign: float) -> tuple[float, float, float]:
    return (xyz[0], sign * xyz[1], xyz[2])


# Masses [kg] of the actuated links; the waist takes the remainder so that the total is exactly 58 kg.
LEG_MASSES_KG = (1.2, 1.0, 4.6, 2.8, 0.7, 1.5)
CHEST_MASSES_KG = (1.2, 13.5)
HEAD_MASSES_KG = (0.4, 1.8)
ARM_MASSES_KG = (0.8, 0.7, 1.6, 1.1, 0.4, 0.75, 0.1)


def _leg(b: _Builder, side: str) -> None:
    """One leg; ``side`` is "R" or "L". Joint limits in degrees follow the HRP-2 model."""
    s = -1.0 if side == "R" else 1.0
    prefix = f"{side}LEG"
    m = LEG_MASSES_KG
    # Hip yaw, roll: ranges mirrored between the legs (outward motion is the larger one).
    yaw_lim = (-45.0, 30.0) if side == "R" else (-30.0, 45.0)
    roll_lim = (-35.0, 17.0) if side == "R" else (-17.0, 35.0)
    ankle_roll_lim = (-20.0, 35.0) if side == "R" else (-35.0, 20.0)
    specs = [
        # name suffix, axis, origin, (lower, upper) deg, velocity rad/s, effort N m
        ("0", (0.0, 0.0, 1.0), (0.0, s * HIP_Y_M, 0.0), yaw_lim, 3.7, 120.0),
        ("1", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), roll_lim, 3.0, 200.0),
        ("2", (0.0, 1.0, 0.0), (0.0, 0.0, 0.0), (-125.0, 42.0), 4.0, 300.0),
        ("3", (0.0, 1.0, 0.0), (0.0, s * THIGH_LATERAL_OFFSET_M, -THIGH_M), (-2.0, 150.0), 4.0, 300.0),
        ("4", (0.0, 1.0, 0.0), (0.0, 0.0, -SHANK_M), (-75.0, 42.0), 4.0, 200.0),
        ("5", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), ankle_roll_lim, 3.0, 150.0),
    ]
    thigh_len = THIGH_M - 0.10
    shank_len = SHANK_M - 0.10
    foot_size = (SOLE_LENGTH_M, SOLE_WIDTH_M, FOOT_THICKNESS_M)
    foot_z = -ANKLE_TO_SOLE_M + FOOT_THICKNESS_M / 2.0
    link_defs = [
        Link(
            f"{prefix}_LINK0",
            m[0],
            (0.0, 0.0, 0.04),
            _cylinder_inertia(m[0], 0.045, 0.08),
            (Shape("cylinder", (0.045, 0.08), (0.0, 0.0, 0.04), colour="silver", collide=False),),
        ),
        Link(
            f"{prefix}_LINK1",
            m[1],
            (0.0, 0.0, 0.0),
            _box_inertia(m[1], (0.09, 0.07, 0.09)),
            (Shape("box", (0.09, 0.07, 0.09), colour="silver", collide=False),),
        ),
        Link(
            f"{prefix}_LINK2",
            m[2],
            (0.0, s * THIGH_LATERAL_OFFSET_M / 2.0, -THIGH_M / 2.0),
            _cylinder_inertia(m[2], 0.065, thigh_len),
            (
                Shape(
                    "cylinder", (0.065, thigh_len), (0.0, s * THIGH_LATERAL_OFFSET_M / 2.0, -THIGH_M / 2.0)
                ),
                Shape("box", (0.1, 0.08, 0.08), (0.0, 0.0, -0.02), colour="blue", collide=False),
            ),
        ),
        Link(
            f"{prefix}_LINK3",
            m[3],
            (0.0, 0.0, -SHANK_M / 2.0),
            _cylinder_inertia(m[3], 0.055, shank_len),
            (
                Shape("cylinder", (0.055, shank_len), (0.0, 0.0, -SHANK_M / 2.0)),
                Shape("sphere", (0.06,), colour="blue", collide=False),
            ),
        ),
        Link(
            f"{prefix}_LINK4",
            m[4],
            (0.0, 0.0, 0.0),
            _box_inertia(m[4], (0.07, 0.07, 0.07)),
            (Shape("box", (0.07, 0.07, 0.07), colour="silver", collide=False),),
        ),
        # Foot: the sole box bottom is exactly ANKLE_TO_SOLE_M below the ankle, flat.
        Link(
            f"{prefix}_LINK5",
            m[5],
            (0.0, 0.0, -0.07),
            _box_inertia(m[5], (0.24, 0.14, 0.07)),
            (
                Shape("box", foot_size, (0.0, 0.0, foot_z), colour="silver"),
                Shape(
                    "box",
                    (0.08, 0.08, ANKLE_TO_SOLE_M - FOOT_THICKNESS_M),
                    (0.0, 0.0, -(ANKLE_TO_SOLE_M - FOOT_THICKNESS_M) / 2.0),
                    colour="blue",
                    collide=False,  # one collision box per foot: the sole, exactly flat
                ),
            ),
        ),
    ]
    parent = b.chain(prefix, "base_link", specs, link_defs)
    sole = "right_sole" if side == "R" else "left_sole"
    b.link(_frame_link(sole))
    b.joint(Joint(f"{sole}_fixed", "fixed", parent, sole, (0.0, 0.0, -ANKLE_TO_SOLE_M)))


def _torso_head(b: _Builder) -> None:
    m_c = CHEST_MASSES_KG
    m_h = HEAD_MASSES_KG
    chest_box = (0.26, 0.34, 0.30)
    chest_centre = (-0.03, 0.0, 0.12)
    backpack = (0.12, 0.28, 0.26)
    backpack_centre = (-0.21, 0.0, 0.13)
    b.link(
        Link(
            "CHEST_LINK0",
            m_c[0],
            (0.0, 0.0, -0.03),
            _cylinder_inertia(m_c[0], 0.06, 0.06),
            (Shape("cylinder", (0.06, 0.06), (0.0, 0.0, -0.03), colour="silver", collide=False),),
        )
    )
    b.joint(
        Joint(
            "CHEST_JOINT0",
            "revolute",
            "base_link",
            "CHEST_LINK0",
            CHEST_JOINT_XYZ,
            axis=(0, 0, 1),
            lower=-45 * DEG,
            upper=45 * DEG,
            velocity=3.0,
            effort=150.0,
        )
    )
    b.link(
        Link(
            "CHEST_LINK1",
            m_c[1],
            (-0.06, 0.0, 0.12),
            _box_inertia(m_c[1], (0.38, 0.34, 0.30)),
            (
                Shape("box", chest_box, chest_centre),
                Shape("box", backpack, backpack_centre, colour="dark"),
                Shape("cylinder", (0.03, 0.06), (0.0, 0.0, 0.27), colour="silver", collide=False),
            ),
        )
    )
    b.joint(
        Joint(
            "CHEST_JOINT1",
            "revolute",
            "CHEST_LINK0",
            "CHEST_LINK1",
            (0.0, 0.0, 0.0),
            axis=(0, 1, 0),
            lower=-5 * DEG,
            upper=60 * DEG,
            velocity=3.0,
            effort=250.0,
        )
    )
    b.link(_frame_link("torso"))
    b.joint(Joint("torso_fixed", "fixed", "CHEST_LINK1", "torso", (0.0, 0.0, 0.0)))

    b.link(
        Link(
            "HEAD_LINK0",
            m_h[0],
            (0.0, 0.0, 0.0),
            _cylinder_inertia(m_h[0], 0.03, 0.05),
            (Shape("cylinder", (0.03, 0.05), colour="silver", collide=False),),
        )
    )
    b.joint(
        Joint(
            "HEAD_JOINT0",
            "revolute",
            "CHEST_LINK1",
            "HEAD_LINK0",
            HEAD_JOINT_XYZ,
            axis=(0, 0, 1),
            lower=-45 * DEG,
            upper=45 * DEG,
            velocity=4.4,
            effort=20.0,
        )
    )
    head_h = 0.194
    head_size = (0.22, 0.18, head_h)
    head_centre = (0.0, 0.0, HEAD_TOP_ABOVE_HEAD_JOINT_M - head_h / 2.0)
    b.link(
        Link(
            "HEAD_LINK1",
            m_h[1],
            head_centre,
            _box_inertia(m_h[1], head_size),
            (
                Shape("box", head_size, head_centre),
                Shape("box", (0.01, 0.17, 0.10), (0.107, 0.0, 0.085), colour="black", collide=False),
            ),
        )
    )
    b.joint(
        Joint(
            "HEAD_JOINT1",
            "revolute",
            "HEAD_LINK0",
            "HEAD_LINK1",
            (0.0, 0.0, 0.0),
            axis=(0, 1, 0),
            lower=-30 * DEG,
            upper=45 * DEG,
            velocity=4.4,
            effort=20.0,
        )
    )
    # Gaze frame: x forward (the gaze axis), midway between the wide-pair cameras.
    b.link(_frame_link("gaze"))
    b.joint(Joint("gaze_fixed", "fixed", "HEAD_LINK1", "gaze", (CAMERA_X_M, 0.0, WIDE_Z_M)))
    for pair, baseline, z in (("wide", WIDE_BASELINE_M, WIDE_Z_M), ("narrow", NARROW_BASELINE_M, NARROW_Z_M)):
        for cam_side, sy in (("left", 1.0), ("right", -1.0)):
            name = f"camera_{pair}_{cam_side}_optical"
            b.link(_frame_link(name))
            b.joint(
                Joint(
                    f"{name}_fixed",
                    "fixed",
                    "HEAD_LINK1",
                    name,
                    (CAMERA_X_M, sy * baseline / 2.0, z),
                    rpy=OPTICAL_RPY,
                )
            )


def _arm(b: _Builder, side: str) -> None:
    """One arm (6 DoF + 1-DoF gripper); ``side`` is "R" or "L"."""
    s = -1.0 if side == "R" else 1.0
    prefix = f"{side}ARM"
    m = ARM_MASSES_KG
    roll_lim = (-95.0, 10.0) if side == "R" else (-10.0, 95.0)
    yaw_lim = (-92.0, 92.0)
    upper_len = UPPER_ARM_M - 0.07
    fore_len = FOREARM_M - 0.07
    specs = [
        ("0", (0.0, 1.0, 0.0), _mirror(SHOULDER_XYZ, s), (-180.0, 60.0), 4.0, 120.0),
        ("1", (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), roll_lim, 4.0, 120.0),
        ("2", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), yaw_lim, 4.0, 60.0),
        ("3", (0.0, 1.0, 0.0), (0.0, 0.0, -UPPER_ARM_M), (-137.0, 0.0), 4.0, 80.0),
        ("4", (0.0, 0.0, 1.0), (0.0, 0.0, -FOREARM_M), (-92.0, 92.0), 4.0, 30.0),
        ("5", (0.0, 1.0, 0.0), (0.0, 0.0, 0.0), (-90.0, 90.0), 4.0, 30.0),
    ]
    palm = (0.07, 0.09, 0.07)
    palm_centre = (0.0, 0.0, -0.05)
    # Fixed finger: inner face at +GRIPPER_OPEN_GAP_M / 2 (mirrored), between z top and top - length.
    finger_z = FINGER_TOP_Z_M - FINGER_LENGTH_M / 2.0
    # Right hand (s = -1): fixed finger at +y (towards the body); left hand: at -y.
    fixed_finger_y = -s * (GRIPPER_OPEN_GAP_M / 2.0 + FINGER_THICKNESS_M / 2.0)
    finger_size = (FINGER_DEPTH_M, FINGER_THICKNESS_M, FINGER_LENGTH_M)
    link_defs = [
        Link(
            f"{prefix}_LINK0",
            m[0],
            (0.0, 0.0, 0.0),
            _cylinder_inertia(m[0], 0.045, 0.09),
            (Shape("cylinder", (0.045, 0.09), rpy=(math.pi / 2, 0.0, 0.0), colour="silver", collide=False),),
        ),
        Link(
            f"{prefix}_LINK1",
            m[1],
            (0.0, 0.0, -0.03),
            _box_inertia(m[1], (0.08, 0.08, 0.08)),
            (Shape("box", (0.08, 0.08, 0.08), (0.0, 0.0, -0.03), colour="blue", collide=False),),
        ),
        Link(
            f"{prefix}_LINK2",
            m[2],
            (0.0, 0.0, -UPPER_ARM_M / 2.0),
            _cylinder_inertia(m[2], 0.045, upper_len),
            (Shape("cylinder", (0.045, upper_len), (0.0, 0.0, -UPPER_ARM_M / 2.0)),),
        ),
        Link(
            f"{prefix}_LINK3",
            m[3],
            (0.0, 0.0, -FOREARM_M / 2.0),
            _cylinder_inertia(m[3], 0.04, fore_len),
            (
                Shape("cylinder", (0.04, fore_len), (0.0, 0.0, -FOREARM_M / 2.0)),
                Shape("sphere", (0.048,), colour="blue", collide=False),
            ),
        ),
        Link(
            f"{prefix}_LINK4",
            m[4],
            (0.0, 0.0, 0.0),
            _cylinder_inertia(m[4], 0.035, 0.05),
            (Shape("cylinder", (0.035, 0.05), colour="silver", collide=False),),
        ),
        Link(
            f"{prefix}_LINK5",
            m[5],
            (0.0, 0.0, -0.07),
            _box_inertia(m[5], (0.07, 0.16, 0.12)),
            (
                Shape("box", palm, palm_centre, colour="dark"),
                Shape(
                    "box",
                    (0.05, GRIPPER_OPEN_GAP_M + 2 * FINGER_THICKNESS_M, 0.01),
                    (0.0, 0.0, FINGER_TOP_Z_M + 0.005),
                    colour="dark",
                ),
                Shape("box", finger_size, (0.0, fixed_finger_y, finger_z), colour="dark"),
            ),
        ),
    ]
    parent = b.chain(prefix, "CHEST_LINK1", specs, link_defs)
    # Moving finger: at q = 0 its inner face is at -GRIPPER_OPEN_GAP_M / 2 (mirrored); it slides towards
    # the fixed finger. Joint origin on the inner face at the top of the finger.
    moving_origin_y = s * (GRIPPER_OPEN_GAP_M / 2.0)
    finger_local_y = s * (FINGER_THICKNESS_M / 2.0)
    finger_centre = (0.0, finger_local_y, -FINGER_LENGTH_M / 2.0)
    b.link(
        Link(
            f"{prefix}_LINK6",
            m[6],
            finger_centre,
            _box_inertia(m[6], finger_size),
            (Shape("box", finger_size, finger_centre, colour="red"),),
        )
    )
    b.joint(
        Joint(
            f"{prefix}_JOINT6",
            "prismatic",
            parent,
            f"{prefix}_LINK6",
            (0.0, moving_origin_y, FINGER_TOP_Z_M),
            axis=(0.0, -s, 0.0),
            lower=0.0,
            upper=GRIPPER_TRAVEL_M,
            velocity=0.1,
            effort=60.0,
        )
    )
    grasp = "right_grasp" if side == "R" else "left_grasp"
    b.link(_frame_link(grasp))
    b.joint(Joint(f"{grasp}_fixed", "fixed", parent, grasp, (0.0, 0.0, -WRIST_TO_GRASP_M)))


def _base(b: _Builder, waist_mass_kg: float) -> None:
    """Waist (hip actuators) and abdomen up to the chest yaw joint: one rigid free-flyer link."""
    waist = (0.20, 0.26, 0.16)
    waist_centre = (0.0, 0.0, 0.06)
    abdomen = (0.16, 0.20, 0.19)
    abdomen_centre = (0.0, 0.0, 0.235)
    com = (0.0, 0.0, 0.10)
    b.links.insert(
        0,
        Link(
            "base_link",
            waist_mass_kg,
            com,
            _box_inertia(waist_mass_kg, (0.20, 0.26, 0.33)),
            (
                Shape("box", waist, waist_centre, colour="silver"),
                Shape("box", abdomen, abdomen_centre, colour="dark"),
            ),
        ),
    )


def build_links_and_joints() -> tuple[list[Link], list[Joint]]:
    """The whole robot as link and joint specs, waist mass set for a 58 kg total."""
    b = _Builder()
    _leg(b, "R")
    _leg(b, "L")
    _torso_head(b)
    _arm(b, "R")
    _arm(b, "L")
    others = sum(link.mass_kg for link in b.links)
    _base(b, TOTAL_MASS_KG - others)
    return b.links, b.joints


def _f(x: float) -> str:
    """Deterministic number formatting (no '-0')."""
    s = f"{x:.10f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _v(values: tuple[float, ...]) -> str:
    return " ".join(_f(v) for v in values)


def _geometry(shape: Shape) -> str:
    if shape.kind == "box":
        return f'<box size="{_v(shape.size)}"/>'
    if shape.kind == "cylinder":
        return f'<cylinder radius="{_f(shape.size[0])}" length="{_f(shape.size[1])}"/>'
    if shape.kind == "sphere":
        return f'<sphere radius="{_f(shape.size[0])}"/>'
    raise ValueError(f"unknown shape kind {shape.kind!r}; expected box, cylinder or sphere")


def urdf_text() -> str:
    """The complete URDF as a string (deterministic)."""
    links, joints = build_links_and_joints()
    out = [
        '<?xml version="1.0"?>',
        "<!-- GENERATED by scripts/gen_hrp2_urdf.py (services/model/generate_urdf.py). Do not edit. -->",
        '<robot name="hrp2_like">',
    ]
    for name, rgba in COLOURS.items():
        out.append(f'  <material name="{name}"><color rgba="{_v(rgba)}"/></material>')
    for link in links:
        out.append(f'  <link name="{link.name}">')
        ixx, iyy, izz = link.inertia
        out.append("    <inertial>")
        out.append(f'      <origin xyz="{_v(link.com_xyz)}" rpy="0 0 0"/>')
        out.append(f'      <mass value="{_f(link.mass_kg)}"/>')
        out.append(
            f'      <inertia ixx="{ixx:.6e}" ixy="0" ixz="0" iyy="{iyy:.6e}" iyz="0" izz="{izz:.6e}"/>'
        )
        out.append("    </inertial>")
        for shape in link.shapes:
            origin = f'<origin xyz="{_v(shape.xyz)}" rpy="{_v(shape.rpy)}"/>'
            out.append("    <visual>")
            out.append(f"      {origin}")
            out.append(f"      <geometry>{_geometry(shape)}</geometry>")
            out.append(f'      <material name="{shape.colour}"/>')
            out.append("    </visual>")
            if not shape.collide:
                continue
            out.append("    <collision>")
            out.append(f"      {origin}")
            out.append(f"      <geometry>{_geometry(shape)}</geometry>")
            out.append("    </collision>")
        out.append("  </link>")
    for j in joints:
        out.append(f'  <joint name="{j.name}" type="{j.kind}">')
        out.append(f'    <parent link="{j.parent}"/>')
        out.append(f'    <child link="{j.child}"/>')
        out.append(f'    <origin xyz="{_v(j.xyz)}" rpy="{_v(j.rpy)}"/>')
        if j.kind != "fixed":
            out.append(f'    <axis xyz="{_v(j.axis)}"/>')
            out.append(
                f'    <limit lower="{_f(j.lower)}" upper="{_f(j.upper)}" '
                f'velocity="{_f(j.velocity)}" effort="{_f(j.effort)}"/>'
            )
        out.append("  </joint>")
    out.append("</robot>")
    return "\n".join(out) + "\n"


def write_urdf(path: Path = DEFAULT_URDF_PATH) -> Path:
    """Write the URDF to ``path`` (default: the committed file) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(urdf_text(), encoding="utf-8")
    return path
