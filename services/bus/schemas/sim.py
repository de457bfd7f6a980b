"""Messages of the ``sim`` service (pybullet world: executes trajectories, renders, grasps).

Configurations follow the pinocchio layout of the simulated robot model (``StateReply.model``):
``q = [x, y, z, qx, qy, qz, qw, joints...]`` (base position [m] and orientation in the world, then
joint positions [rad], or [m] for prismatic grippers), ``v = [base linear, base angular (base frame),
joint velocities]``; ``StateReply.joint_names`` gives the joint order. Times are sim time [s].
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np
from msgspec import Meta

from services.bus.limits import Budget, Coord, ImageSide, Name, Names, Phase, Point3, SceneName, Seed
from services.bus.spec import EndpointSpec, TopicSpec

# ---------------------------------------------------------------------------------------------- topics


class JointState(msgspec.Struct, kw_only=True, frozen=True):
    """Robot state, published every 5 ms of sim time while physics runs."""

    sim_time_s: float
    q: np.ndarray  # (nq,) float64 configuration, pinocchio layout [m, -, rad]
    v: np.ndarray  # (nv,) float64 velocity [m/s, rad/s]


class BasePose(msgspec.Struct, kw_only=True, frozen=True):
    """Pose of the robot's base (waist) frame in the world, published with each JointState."""

    sim_time_s: float
    position: list[float]  # [x, y, z] of the base frame origin [m]
    quaternion: list[float]  # [qx, qy, qz, qw] orientation of the base frame
    linear_velocity: list[float]  # velocity of the base's centre of mass, world frame [m/s]
    angular_velocity: list[float]  # world frame [rad/s]


class Clock(msgspec.Struct, kw_only=True, frozen=True):
    """Sim time, every 5 ms of it. Monotonic for the life of the service (a reset does not rewind it)."""

    sim_time_s: float


JOINT_STATE = TopicSpec("sim", "joint_state", JointState, "robot q, v and sim time at 200 Hz of sim time")
BASE_POSE = TopicSpec("sim", "base_pose", BasePose, "base pose and velocity at 200 Hz of sim time")
CLOCK = TopicSpec("sim", "clock", Clock, "sim time at 200 Hz of sim time")

# ---------------------------------------------------------------------------------------------- state


class StateRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """No fields: asks for the current state."""


class StateReply(msgspec.Struct, kw_only=True, frozen=True):
    sim_time_s: float
    model: str  # robot model name (services.model.load_robot)
    scene: str  # current scene name
    seed: int | None  # seed of the current layout (None: nominal)
    joint_names: list[str]  # actuated joints in q order (after the 7 base coordinates)
    q: np.ndarray  # (nq,) configuration
    v: np.ndarray  # (nv,) velocity
    held: dict[str, str]  # side ("left"/"right") -> name of the object held, for each hand holding one
    fallen: bool  # base below the fall height or tilted beyond the fall angle


STATE = EndpointSpec("sim", "state", StateRequest, StateReply, "current q, v, held objects and sim time")

# ---------------------------------------------------------------------------------------------- execute


class ExecuteRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A whole-body trajectory played through position control of every joint."""

    q: np.ndarray  # (N, nq) configurations every dt_s; q[0] is the start (within 0.2 rad of the state)
    dt_s: Annotated[float, Meta(gt=0.0, le=0.1)] = 0.005  # sample period [s], a multiple of 1 ms
    allowed_contacts: Names = []  # objects the hands / held objects may touch (grasp target, table)
    stop_on_collision: bool = True  # stop at the first unplanned contact (else report at the end)
    hold_s: Phase = 0.0  # keep commanding the last sample this long after the end [s]
    # Objects the robot touches at the start and moves away from (backing out of a collision): any link
    # may keep touching one of them until that contact first breaks; touching it again is a collision.
    leaving: Names = []
    # Objects any link may touch during the whole motion: the supports of a multi-contact motion (the
    # chair the robot gets up from, the table it leans on), chosen by the contact planner.
    supports: Names = []
    # Joint name -> fraction in (0, 1] of its effort limit, for this execution only: a compliant limb in
    # a closed kinematic loop (the arm of a hand on a table while a sole holds the robot). {}: full effort.
    effort_scale: dict[str, float] = {}
    # Wall-clock limit of the execution [s]: past it the robot holds where it is and the reply is a
    # timeout error saying how much was played. None: the sim's execute_budget_s (300 s by default).
    time_budget_s: Annotated[float, Meta(gt=0.0, le=600.0)] | None = None


class Contact(msgspec.Struct, kw_only=True, frozen=True):
    """An unplanned contact: a robot link (or ``held:<object>``) touching a scene object or the floor."""

    robot_link: str
    other: str
    position: list[float]  # world [m]
    normal_force_n: float  # [N]


class ExecuteReply(msgspec.Struct, kw_only=True, frozen=True):
    """How the execution ended; ``outcome`` is ``completed``, ``fell`` or ``collision``."""

    outcome: str
    message: str  # what happened, for people
    sim_time_s: float  # at the end
    duration_s: float  # sim time spent executing [s]
    samples_executed: int
    q: np.ndarray  # (nq,) final configuration
    v: np.ndarray  # (nv,) final velocity
    tracking_error_rad: float  # max |commanded - measured| joint position (grippers excluded) [rad]
    tracking_rms_rad: float  # RMS joint tracking error [rad]
    worst_joint: str  # joint of the max tracking error
    base_error_m: float  # max distance between measured and planned base position [m]
    foot_slip_m: float  # max horizontal drift of a loaded sole [m]
    collisions: list[Contact] = []  # unplanned contacts (first point of each pair)
    fall_base_height_m: float = 0.0  # base height when a fall was detected [m]
    fall_tilt_rad: float = 0.0  # base tilt when a fall was detected [rad]


EXECUTE = EndpointSpec(
    "sim",
    "execute",
    ExecuteRequest,
    ExecuteReply,
    "play a 5 ms whole-body trajectory; completed | fell | collision with tracking error and foot slip",
)

# ---------------------------------------------------------------------------------------------- render


class RenderRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    camera: Name = "wide"  # a stereo pair ("wide": 0.144 m baseline, "narrow": 0.058 m) or one camera
    width_px: ImageSide = 640
    height_px: ImageSide = 480
    depth: bool = False  # also return depth along the optical axis
    segmentation: bool = False  # also return a per-pixel body id mask (see CameraImage.labels)
    # the wait for the world and the draws [s] (a draw estimated to end past it is not started:
    # ``timeout``); None: no budget (the image sides bound the work)
    time_budget_s: Budget | None = None


class CameraImage(msgspec.Struct, kw_only=True, frozen=True):
    """One image. Pixel (row i, column j) is centred at (u, v) = (j + 0.5, i + 0.5); a point at
    (X, Y, Z) in the optical frame (z forward, x right, y down) projects to u = fx X/Z + cx,
    v = fy Y/Z + cy."""

    name: str  # camera name, e.g. "wide_left"
    width_px: int
    height_px: int
    K: np.ndarray  # (3, 3) intrinsics [px]
    T_world_camera: np.ndarray  # (4, 4) pose of the optical frame at render time
    rgb: np.ndarray  # (H, W, 3) uint8
    depth_m: np.ndarray | None = None  # (H, W) float32 depth along the optical axis [m]
    segmentation: np.ndarray | None = None  # (H, W) int32 body id, -1 where nothing was drawn
    labels: dict[int, str] = {}  # body id -> "robot", "floor" or the object name


class RenderReply(msgspec.Struct, kw_only=True, frozen=True):
    sim_time_s: float
    images: list[CameraImage]  # left then right for a pair
    baseline_m: float = 0.0  # stereo baseline of a pair [m] (0 for a single camera)


RENDER = EndpointSpec("sim", "render", RenderRequest, RenderReply, "images of a head stereo pair or camera")

# ---------------------------------------------------------------------------------------------- gripper


class GripperRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    side: Name  # "left" or "right"
    action: Name  # "open" or "close"


class GripperReply(msgspec.Struct, kw_only=True, frozen=True):
    """``outcome``: ``grasped`` (``held`` names the object), ``not_grasped`` (nothing between the jaws),
    ``released`` (``released`` names the object let go) or ``opened``."""

    side: str
    action: str
    outcome: str
    held: str  # object now held by this hand, "" if none
    released: str  # object just released, "" if none
    finger_q: float  # gripper joint after the motion [m or rad]
    sim_time_s: float


GRIPPER = EndpointSpec(
    "sim", "gripper", GripperRequest, GripperReply, "open or close a gripper; grasps on contact"
)

# ---------------------------------------------------------------------------------------------- reset


class ResetRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    scene: SceneName = ""  # scene name (a file <name>.yaml of the sim's scene folders); "": the current one
    seed: Seed | None = None  # layout seed; None: the scene's nominal layout


class ResetReply(msgspec.Struct, kw_only=True, frozen=True):
    scene: str
    seed: int | None
    objects: list[str]  # names of the scene objects
    q: np.ndarray  # (nq,) robot configuration after the reset (half-sitting at the start pose)
    sim_time_s: float


RESET = EndpointSpec(
    "sim", "reset", ResetRequest, ResetReply, "reload a scene (optionally randomized) and the robot"
)

# ---------------------------------------------------------------------------------------------- ground truth


class GroundTruthRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """No fields."""


class ObjectState(msgspec.Struct, kw_only=True, frozen=True):
    """One scene object: the pose of its reference point (centre of boxes, balls and bars; floor
    centre of tables and chairs) and its description."""

    name: str
    kind: str  # box, table, chair, ball, bar, disk
    position: list[float]  # [m] world
    quaternion: list[float]  # [qx, qy, qz, qw]
    colour: list[float]  # [r, g, b, a] in [0, 1]
    size_m: list[float]  # box: extents; table/chair: [sx, sy, height] [m]; else zeros
    radius_m: float  # ball, bar, disk [m]
    length_m: float  # bar [m]
    mass_kg: float  # 0 for static objects
    held_by: str  # "", "left" or "right"


class GroundTruthReply(msgspec.Struct, kw_only=True, frozen=True):
    sim_time_s: float
    scene: str
    seed: int | None
    base_position: list[float]  # robot base frame [m]
    base_quaternion: list[float]  # [qx, qy, qz, qw]
    objects: list[ObjectState]


GROUND_TRUTH = EndpointSpec(
    "sim",
    "ground_truth",
    GroundTruthRequest,
    GroundTruthReply,
    "object and robot poses - for tests and benchmarks only (planners and supervisor must not use it)",
)

# ---------------------------------------------------------------------------------------------- snapshot


class SnapshotRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    viewpoint: Name = "overview"  # overview, front, side, back, top (around the robot and the scene)
    width_px: ImageSide = 640
    height_px: ImageSide = 480
    eye: Point3 | None = None  # custom camera position [m] (with target)
    target: Point3 | None = None  # custom point looked at [m] (with eye)
    time_budget_s: Budget | None = None  # as RenderRequest's: the wait for the world and the draw [s]


class SnapshotReply(msgspec.Struct, kw_only=True, frozen=True):
    sim_time_s: float
    png: np.ndarray  # (n,) uint8: the bytes of a PNG file


SNAPSHOT = EndpointSpec(
    "sim", "snapshot", SnapshotRequest, SnapshotReply, "a PNG of the world from an external camera"
)


# ------------------------------------------------------------------------------------- robot facts


class RobotInfoRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """No fields: the facts of the simulated robot model."""


class RobotInfoReply(msgspec.Struct, kw_only=True, frozen=True):
    """What a client that does not load the model (the supervisor) needs to know of the robot (the
    head's joints and views: ``perception/look_around``).

    Joint values are in the pinocchio ``q`` layout (``q_*`` arrays (nq,): base [x, y, z, qx, qy, qz, qw],
    then the joints of ``joint_names``); frame names are those ``sim/kinematics`` takes.
    """

    model: str
    nq: int
    joint_names: list[str]
    q_half_sitting: np.ndarray  # (nq,)
    q_lower: np.ndarray  # (nq,) joint lower limits (base coordinates: -inf)
    q_upper: np.ndarray  # (nq,)
    chest_joints: list[str]  # straightened (half-sitting values) before a walk
    gripper_joints: dict[str, str]  # side -> joint (moved by sim/gripper only)
    frames: dict[str, str]  # role -> frame: left_sole, right_sole, left_grasp, right_grasp, gaze, torso
    fixed_finger_y_m: dict[str, float]  # side -> y of the fixed finger in the grasp frame [m] (0: symmetric)
    cameras: dict[str, list[int]]  # camera name -> [width, height] of its images [px]
    stereo_pairs: dict[str, list[str]]  # pair name ("wide", "narrow") -> [left camera, right camera]


ROBOT_INFO = EndpointSpec(
    "sim", "robot_info", RobotInfoRequest, RobotInfoReply, "the robot model's joints, frames, cameras"
)


class KinematicsRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Forward kinematics of the robot model at configurations ``q`` ((k, nq) or (nq,)).

    ``frames``: frame names (``RobotInfoReply.frames`` values) whose world poses to return.
    ``place_at``: [x, y, yaw] ([m], [m], [rad]): also return the last configuration moved so that its
    mid-feet frame is there and its soles at z = 0 (joints unchanged). ``time_budget_s``: see below.
    """

    q: np.ndarray
    frames: Names = []
    place_at: Annotated[list[Coord], Meta(max_length=3)] = []
    # wall-clock budget [s]: past it, ``timeout`` naming the configuration reached; None: no budget (the
    # configuration and frame-pose limits bound the work)
    time_budget_s: Budget | None = None


class KinematicsReply(msgspec.Struct, kw_only=True, frozen=True):
    """Per configuration: the mid-feet pose on the ground ``mid_feet`` (k, 3) [x, y, yaw], the sole
    heights ``sole_z_m`` (k, 2) [left, right] [m], the requested frames' world poses ``poses``
    (k, n_frames, 4, 4) (homogeneous, [m]); ``q_placed`` (nq,) when ``place_at`` was given (else empty)."""

    mid_feet: np.ndarray
    sole_z_m: np.ndarray
    poses: np.ndarray
    q_placed: np.ndarray


KINEMATICS = EndpointSpec(
    "sim", "kinematics", KinematicsRequest, KinematicsReply, "mid-feet pose, sole heights, frame poses at q"
)
