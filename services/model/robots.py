"""Per-robot descriptions: which URDF, which frames play which role, half-sitting, capsules, cameras.

Everything robot-specific that is not in the URDF lives here (numbers) or in the robot's parameter
YAML (planner tuning). :func:`services.model.load_robot` turns a description into a
:class:`~services.model.robot_model.RobotModel`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from services.model import generate_urdf as gen
from services.model.paths import DATA_DIR, example_robot_data_share, talos_data_dir
from services.model.specs import CameraSpec, RobotFrames, StereoPair

Vec3 = tuple[float, float, float]
OPTICAL_RPY: Vec3 = gen.OPTICAL_RPY


@dataclass(frozen=True)
class ExtraFrame:
    """A frame added to the pinocchio model at load time (not in the URDF), rigidly attached to the
    frame ``parent_frame`` at ``xyz`` [m] / ``rpy`` [rad] (URDF fixed-axis convention)."""

    name: str
    parent_frame: str
    xyz: Vec3
    rpy: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CapsuleSpec:
    """A capsule on ``frame`` from ``p0_local`` to ``p1_local`` [m]; if ``p1_frame`` is given, ``p1`` is
    that frame's origin expressed in ``frame`` (it must be rigidly attached to ``frame``: a child joint
    origin)."""

    name: str
    frame: str
    p0_local: Vec3
    radius_m: float
    p1_local: Vec3 | None = None
    p1_frame: str | None = None


@dataclass(frozen=True)
class RobotDescription:
    """Everything :func:`load_robot` needs to build a :class:`RobotModel`."""

    name: str
    urdf_path: Path
    package_dirs: tuple[Path, ...]
    params_path: Path
    frames: RobotFrames
    extra_frames: tuple[ExtraFrame, ...]
    half_sitting: dict[str, float]
    arm_joints: dict[str, tuple[str, ...]]
    gripper_joints: dict[str, str]
    cameras: dict[str, CameraSpec]
    stereo_pairs: dict[str, StereoPair]
    capsules: tuple[CapsuleSpec, ...]
    sole_size_m: tuple[float, float]
    # y [m] in the grasp frame of the fixed finger's inner face per side (one-moving-finger grippers),
    # or None when the fingers close symmetrically about the grasp frame.
    fixed_finger_y_m: dict[str, float] | None = None
    # pybullet only (the pinocchio model keeps the URDF shapes): if set, each foot's collision shapes are
    # replaced with one box of the sole rectangle, this thick [m], whose bottom face is the sole frame.
    pybullet_sole_box_m: float | None = None
    # pybullet constraint-solver iterations per physics step this robot needs (sim default).
    pybullet_solver_iterations: int = 20
    notes: str = ""


def _capsule_pairs(names: set[str]) -> tuple[tuple[str, str], ...]:
    """Self-collision pairs worth checking (same rules for every robot; capsule names are shared).

    Hands and forearms against the trunk, head, thighs and the other arm; the legs against each other.
    Neighbouring bodies (which always touch through their joints) are never paired.
    """
    pairs: list[tuple[str, str]] = []
    for s, o in (("l", "r"), ("r", "l")):
        for other in ("chest", "waist", "head", f"{s}_thigh", f"{o}_thigh", f"{o}_hand", f"{o}_forearm"):
            pairs.append((f"{s}_hand", other))
        for other in ("chest", "waist", f"{s}_thigh"):
            pairs.append((f"{s}_forearm", other))
        pairs.append((f"{s}_shank", f"{o}_foot"))
    pairs += [
        ("l_forearm", "r_forearm"),
        ("l_thigh", "r_thigh"),
        ("l_shank", "r_shank"),
        ("l_foot", "r_foot"),
    ]
    unique: list[tuple[str, str]] = []
    seen: set[frozenset[str]] = set()
    for a, b in pairs:
        key = frozenset((a, b))
        if key in seen:
            continue
        seen.add(key)
        missing = {a, b} - names
        if missing:
            raise ValueError(f"collision pair ({a}, {b}) names unknown capsules {sorted(missing)}")
        unique.append((a, b))
    return tuple(unique)


def collision_pairs_for(capsules: tuple[CapsuleSpec, ...]) -> tuple[tuple[str, str], ...]:
    """The checked pairs of capsule names for a capsule set."""
    return _capsule_pairs({c.name for c in capsules})


def _pinhole(frame: str, hfov_deg: float, width_px: int = 640, height_px: int = 480) -> CameraSpec:
    """A square-pixel pinhole camera; principal point at the image centre (pixel (0, 0) is the top-left
    corner of the top-left pixel)."""
    f = (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    return CameraSpec(width_px, height_px, f, f, width_px / 2.0, height_px / 2.0, frame=frame)


# Camera fields of view [deg]: the wide-baseline (lower) pair looks far with 60 deg, the
# narrow-baseline (upper) pair near with 90 deg. Both 640x480 (HRP-2's firewire cameras).
WIDE_HFOV_DEG = 60.0
NARROW_HFOV_DEG = 90.0


def _cameras(prefix: str = "camera_") -> tuple[dict[str, CameraSpec], dict[str, StereoPair]]:
    cameras = {
        f"{pair}_{side}": _pinhole(f"{prefix}{pair}_{side}_optical", fov)
        for pair, fov in (("wide", WIDE_HFOV_DEG), ("narrow", NARROW_HFOV_DEG))
        for side in ("left", "right")
    }
    pairs = {
        "wide": StereoPair("wide_left", "wide_right", gen.WIDE_BASELINE_M),
        "narrow": StereoPair("narrow_left", "narrow_right", gen.NARROW_BASELINE_M),
    }
    return cameras, pairs


def hrp2_like() -> RobotDescription:
    """The generated HRP-2-like robot (services/model/data/hrp2_like.urdf)."""
    deg = math.pi / 180.0
    half_sitting: dict[str, float] = {}
    for side in ("R", "L"):
        s = -1.0 if side == "R" else 1.0
        half_sitting |= {
            f"{side}LEG_JOINT0": 0.0,
            f"{side}LEG_JOINT1": 0.0,
            f"{side}LEG_JOINT2": -0.4538,
            f"{side}LEG_JOINT3": 0.8727,
            f"{side}LEG_JOINT4": -0.4189,
            f"{side}LEG_JOINT5": 0.0,
            # HRP-2 half-sitting arms: shoulder pitch 15, roll -+10, elbow -30 deg.
            f"{side}ARM_JOINT0": 15.0 * deg,
            f"{side}ARM_JOINT1": s * 10.0 * deg,
            f"{side}ARM_JOINT2": 0.0,
            f"{side}ARM_JOINT3": -30.0 * deg,
            f"{side}ARM_JOINT4": 0.0,
            f"{side}ARM_JOINT5": 0.0,
            f"{side}ARM_JOINT6": 0.0,  # gripper open
        }
    half_sitting |= {"CHEST_JOINT0": 0.0, "CHEST_JOINT1": 0.0, "HEAD_JOINT0": 0.0, "HEAD_JOINT1": 0.0}
    capsules: list[CapsuleSpec] = [
        CapsuleSpec("waist", "base_link", (0.0, 0.0, 0.05), 0.11, p1_local=(0.0, 0.0, 0.24)),
        CapsuleSpec("chest", "CHEST_LINK1", (-0.05, 0.0, 0.02), 0.17, p1_local=(-0.05, 0.0, 0.22)),
        CapsuleSpec("head", "HEAD_LINK1", (0.0, 0.0, 0.07), 0.11, p1_local=(0.0, 0.0, 0.11)),
    ]
    for side, c in (("L", "l"), ("R", "r")):
        s = 1.0 if side == "L" else -1.0
        capsules += [
            CapsuleSpec(
                f"{c}_upper_arm", f"{side}ARM_LINK2", (0.0, 0.0, -0.03), 0.05, p1_local=(0.0, 0.0, -0.22)
            ),
            CapsuleSpec(
                f"{c}_forearm", f"{side}ARM_LINK3", (0.0, 0.0, 0.0), 0.045, p1_local=(0.0, 0.0, -0.21)
            ),
            CapsuleSpec(
                f"{c}_hand", f"{side}ARM_LINK5", (0.0, 0.0, -0.03), 0.075, p1_local=(0.0, 0.0, -0.13)
            ),
            CapsuleSpec(
                f"{c}_thigh",
                f"{side}LEG_LINK2",
                (0.0, s * 0.01, -0.06),
                0.06,
                p1_local=(0.0, s * gen.THIGH_LATERAL_OFFSET_M, -0.26),
            ),
            CapsuleSpec(
                f"{c}_shank", f"{side}LEG_LINK3", (0.0, 0.0, -0.03), 0.06, p1_local=(0.0, 0.0, -0.26)
            ),
            CapsuleSpec(
                f"{c}_foot", f"{side}LEG_LINK5", (-0.08, 0.0, -0.06), 0.045, p1_local=(0.08, 0.0, -0.06)
            ),
        ]
    cameras, pairs = _cameras()
    return RobotDescription(
        name="hrp2_like",
        urdf_path=DATA_DIR / "hrp2_like.urdf",
        package_dirs=(DATA_DIR,),
        params_path=DATA_DIR / "hrp2_like.yaml",
        frames=RobotFrames(
            left_sole="left_sole",
            right_sole="right_sole",
            left_grasp="left_grasp",
            right_grasp="right_grasp",
            gaze="gaze",
            torso="torso",
            base="base_link",
        ),
        extra_frames=(),
        half_sitting=half_sitting,
        arm_joints={
            "left": tuple(f"LARM_JOINT{i}" for i in range(6)),
            "right": tuple(f"RARM_JOINT{i}" for i in range(6)),
        },
        gripper_joints={"left": "LARM_JOINT6", "right": "RARM_JOINT6"},
        cameras=cameras,
        stereo_pairs=pairs,
        capsules=tuple(capsules),
        sole_size_m=(gen.SOLE_LENGTH_M, gen.SOLE_WIDTH_M),
        fixed_finger_y_m={"right": gen.GRIPPER_OPEN_GAP_M / 2.0, "left": -gen.GRIPPER_OPEN_GAP_M / 2.0},
    )


# TALOS half-sitting from example-robot-data's talos.srdf ("half_sitting"), except the ankle rolls
# (-0.001708 rad there) set to 0 so that the soles are exactly flat.
_TALOS_HALF_SITTING: dict[str, float] = {
    "arm_left_1_joint": 0.25847,
    "arm_left_2_joint": 0.173046,
    "arm_left_3_joint": -0.0002,
    "arm_left_4_joint": -0.525366,
    "arm_left_5_joint": 0.0,
    "arm_left_6_joint": 0.0,
    "arm_left_7_joint": 0.1,
    "arm_right_1_joint": -0.25847,
    "arm_right_2_joint": -0.173046,
    "arm_right_3_joint": 0.0002,
    "arm_right_4_joint": -0.525366,
    "arm_right_5_joint": 0.0,
    "arm_right_6_joint": 0.0,
    "arm_right_7_joint": 0.1,
    "head_1_joint": 0.0,
    "head_2_joint": 0.0,
    "leg_left_1_joint": 0.0,
    "leg_left_2_joint": 0.0,
    "leg_left_3_joint": -0.411354,
    "leg_left_4_joint": 0.859395,
    "leg_left_5_joint": -0.448041,
    "leg_left_6_joint": 0.0,
    "leg_right_1_joint": 0.0,
    "leg_right_2_joint": 0.0,
    "leg_right_3_joint": -0.411354,
    "leg_right_4_joint": 0.859395,
    "leg_right_5_joint": -0.448041,
    "leg_right_6_joint": 0.0,
    "torso_1_joint": 0.0,
    "torso_2_joint": 0.006761,
    "gripper_left_joint": 0.0,
    "gripper_right_joint": 0.0,
}

# Synthetic TALOS head cameras (TALOS has an RGB-D camera, not two stereo pairs): the same two stereo
# pairs as hrp2_like, mounted just in front of the head shell (head_2_link frame) so renders are not
# occluded by the head's own collision mesh.
_TALOS_CAMERA_X_M = 0.125
_TALOS_WIDE_Z_M = 0.19
_TALOS_NARROW_Z_M = 0.23
# Grasp point: centre between the three fingertip links, in the arm_*_7_link frame.
_TALOS_GRASP_Z_M = -0.214


def talos() -> RobotDescription:
    """TALOS (talos_reduced.urdf from example-robot-data), with synthetic stereo cameras and grasp frames."""
    data = talos_data_dir()
    extra: list[ExtraFrame] = [
        ExtraFrame("gaze", "head_2_link", (_TALOS_CAMERA_X_M, 0.0, _TALOS_WIDE_Z_M)),
        ExtraFrame("left_grasp", "arm_left_7_link", (0.0, 0.0, _TALOS_GRASP_Z_M)),
        ExtraFrame("right_grasp", "arm_right_7_link", (0.0, 0.0, _TALOS_GRASP_Z_M)),
    ]
    for pair, baseline, z in (
        ("wide", gen.WIDE_BASELINE_M, _TALOS_WIDE_Z_M),
        ("narrow", gen.NARROW_BASELINE_M, _TALOS_NARROW_Z_M),
    ):
        for side, sy in (("left", 1.0), ("right", -1.0)):
            extra.append(
                ExtraFrame(
                    f"camera_{pair}_{side}_optical",
                    "head_2_link",
                    (_TALOS_CAMERA_X_M, sy * baseline / 2.0, z),
                    OPTICAL_RPY,
                )
            )
    capsules: list[CapsuleSpec] = [
        CapsuleSpec("waist", "base_link", (-0.04, -0.1, -0.09), 0.11, p1_local=(-0.04, 0.1, -0.09)),
        CapsuleSpec("chest", "torso_2_link", (-0.06, 0.0, 0.10), 0.16, p1_local=(-0.06, 0.0, 0.24)),
        CapsuleSpec("head", "head_2_link", (0.005, 0.0, 0.16), 0.11, p1_local=(0.005, 0.0, 0.21)),
    ]
    for side, c in (("left", "l"), ("right", "r")):
        capsules += [
            CapsuleSpec(
                f"{c}_upper_arm", f"arm_{side}_3_link", (0.0, 0.0, -0.05), 0.06, p1_frame=f"arm_{side}_4_link"
            ),
            CapsuleSpec(
                f"{c}_forearm", f"arm_{side}_4_link", (0.0, 0.0, 0.0), 0.06, p1_frame=f"arm_{side}_5_link"
            ),
            CapsuleSpec(
                f"{c}_hand", f"arm_{side}_7_link", (0.0, 0.0, -0.05), 0.07, p1_local=(0.0, 0.0, -0.19)
            ),
            CapsuleSpec(
                f"{c}_thigh", f"leg_{side}_3_link", (0.0, 0.0, -0.06), 0.08, p1_frame=f"leg_{side}_4_link"
            ),
            CapsuleSpec(
                f"{c}_shank", f"leg_{side}_4_link", (0.0, 0.0, -0.03), 0.07, p1_frame=f"leg_{side}_5_link"
            ),
            CapsuleSpec(
                f"{c}_foot", f"leg_{side}_6_link", (-0.08, 0.0, -0.065), 0.04, p1_local=(0.07, 0.0, -0.065)
            ),
        ]
    cameras, pairs = _cameras()
    return RobotDescription(
        name="talos",
        urdf_path=data / "robots" / "talos_reduced.urdf",
        package_dirs=(example_robot_data_share(),),
        params_path=DATA_DIR / "talos.yaml",
        frames=RobotFrames(
            left_sole="left_sole_link",
            right_sole="right_sole_link",
            left_grasp="left_grasp",
            right_grasp="right_grasp",
            gaze="gaze",
            torso="torso_2_link",
            base="base_link",
        ),
        extra_frames=tuple(extra),
        half_sitting=dict(_TALOS_HALF_SITTING),
        arm_joints={side: tuple(f"arm_{side}_{i}_joint" for i in range(1, 8)) for side in ("left", "right")},
        gripper_joints={"left": "gripper_left_joint", "right": "gripper_right_joint"},
        cameras=cameras,
        stereo_pairs=pairs,
        capsules=tuple(capsules),
        # Foot size from talos.srdf <specificities> (0.205 x 0.122 m), inside the collision mesh footprint.
        sole_size_m=(0.205, 0.122),
        # The foot collision mesh (ankle_X_collision.stl) has a convex, non-flat bottom (1.9 mm of relief,
        # lowest vertex 0.4 mm below the sole frame): pybullet supports the foot on 1-4 of its vertices and
        # the stance foot rocks until the robot falls while walking. A box of the sole size is flat.
        pybullet_sole_box_m=0.02,
        # Heavier links and stiff position motors: on rigid flat soles, with 20 iterations the side steps
        # and arcs fell; on the damped sole contact 20 suffice (arc 0.7 mm off), 50 track closer (0.3 mm).
        pybullet_solver_iterations=50,
        notes="cameras, gaze and grasp frames are synthetic (added at load time, not in the URDF)",
    )


DESCRIPTIONS: dict[str, Callable[[], RobotDescription]] = {"hrp2_like": hrp2_like, "talos": talos}
