"""Looking around for an object that is not in view: head pan/tilt scan, then turning (pure, no bus).

Where this runs: in the **supervisor**, not in the perception service. Only the sim executes motion and
``perception/locate`` is a stateless request -> reply (the camera pose comes from the ``q`` in the
request), so the supervisor drives the search:

1. ``perception/locate`` -> ``not_found`` with ``details["reason"] == "not_in_view"``;
2. for each ``(pan, tilt)`` of :func:`scan_angles`: send :func:`head_trajectory` to ``sim/execute``,
   then ``perception/locate`` again with the new ``q``; stop at the first success;
3. still not found: turn the body on the spot by each of :func:`turn_offsets` (relative to the
   heading at the start of the search; footsteps/walking plan the turn), scan again.

``ambiguous`` is not a reason to look around (the object is in view twice): move closer or change the
viewpoint instead.

The head joints are found from the kinematic chain of the stereo pair's left camera (its two closest
joints), and told apart by their effect on the gaze: the pan joint turns the optical axis sideways, the
tilt joint up/down. Tilt angles are therefore given as gaze *depression* below the horizontal [rad]
(positive = looking down) and converted to joint values with the right sign for each robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.errors import InvalidRequestError
from services.model import RobotModel
from services.model.ground import smoothstep5
from services.perception.locate import stereo_pair

#: Default gaze depressions of the scan rows [rad]: 20 deg sees tables and boxes from 1.3 m to far away,
#: 40 deg the floor from 0.7 m to 4 m (HRP-2 wide pair: 47 deg vertical field of view at 1.36 m).
DEFAULT_DEPRESSIONS_RAD = (0.35, 0.7)


@dataclass(frozen=True)
class HeadJoints:
    """The two head joints moving a stereo pair's gaze.

    pan, tilt: joint names; *_limits: (lower, upper) [rad]; tilt_sign: +1 when increasing the tilt joint
    lowers the gaze, -1 otherwise; hfov_rad, vfov_rad: the left camera's fields of view [rad].
    """

    pan: str
    tilt: str
    pan_limits: tuple[float, float]
    tilt_limits: tuple[float, float]
    tilt_sign: float
    hfov_rad: float
    vfov_rad: float


def _gaze(robot: RobotModel, q: np.ndarray, camera: str) -> np.ndarray:
    """Optical axis (unit, world) of ``camera`` at ``q``."""
    return robot.camera_pose(q, camera, robot.new_data()).rotation[:, 2].copy()


def head_joints(robot: RobotModel, camera: str = "wide") -> HeadJoints:
    """The pan and tilt joints of stereo pair ``camera`` (InvalidRequestError if the head cannot move)."""
    pair = stereo_pair(robot, camera)
    spec = robot.cameras[pair.left]
    model = robot.model
    joint = model.frames[robot.frame_id(spec.frame)].parentJoint
    chain = []
    while joint > 0 and len(chain) < 2:
        chain.append(model.names[joint])
        joint = model.parents[joint]
    if len(chain) < 2 or any(n not in robot.joint_names for n in chain):
        raise InvalidRequestError(f"{robot.name}: the {camera} cameras are not on a two-joint head")
    q0 = robot.q_half_sitting.copy()
    g0, h = _gaze(robot, q0, pair.left), 1e-4
    effect = {}
    for name in chain:
        q = q0.copy()
        q[robot.joint_index(name).idx_q] += h
        d = (_gaze(robot, q, pair.left) - g0) / h
        effect[name] = float(d[2])  # rate of change of the gaze's vertical component
    # The tilt joint raises or lowers the (horizontal, in half-sitting) gaze; the pan joint does not.
    tilt = max(chain, key=lambda n: abs(effect[n]))
    pan = next(n for n in chain if n != tilt)
    lo, hi = robot.q_lower, robot.q_upper
    ip, it = robot.joint_index(pan).idx_q, robot.joint_index(tilt).idx_q
    return HeadJoints(
        pan=pan,
        tilt=tilt,
        pan_limits=(float(lo[ip]), float(hi[ip])),
        tilt_limits=(float(lo[it]), float(hi[it])),
        tilt_sign=-1.0 if effect[tilt] > 0 else 1.0,
        hfov_rad=spec.hfov_rad,
        vfov_rad=spec.vfov_rad,
    )


def _columns(lo: float, hi: float, fov: float, overlap: float) -> list[float]:
    """Evenly spaced angles from lo to hi [rad], neighbours at most fov * (1 - overlap) apart."""
    step = fov * (1.0 - overlap)
    n = max(1, math.ceil((hi - lo) / step - 1e-9)) + 1
    return [lo + (hi - lo) * k / (n - 1) for k in range(n)]


def scan_angles(
    robot: RobotModel,
    camera: str = "wide",
    depressions_rad: tuple[float, ...] = DEFAULT_DEPRESSIONS_RAD,
    overlap: float = 0.25,
    start_pan_rad: float = 0.0,
) -> list[tuple[float, float]]:
    """Head joint values ``(pan, tilt)`` [rad] to visit in order, sweeping the whole pan range.

    One row of pan angles per gaze depression (in the given order), neighbouring views overlapping by
    ``overlap`` of the horizontal field of view; the first row starts at the pan nearest
    ``start_pan_rad`` and each next row starts at the end where the previous one stopped. Tilts are
    clipped to the joint limits.
    """
    if not 0.0 <= overlap < 1.0:
        raise InvalidRequestError(f"overlap must be in [0, 1), got {overlap}")
    if not depressions_rad:
        raise InvalidRequestError("give at least one gaze depression")
    head = head_joints(robot, camera)
    pans = _columns(*head.pan_limits, head.hfov_rad, overlap)
    nearest = min(range(len(pans)), key=lambda k: abs(pans[k] - start_pan_rad))
    # First row: nearest column, then outwards alternately, so that what is ahead is seen first.
    first = sorted(range(len(pans)), key=lambda k: (abs(k - nearest), k < nearest))
    out: list[tuple[float, float]] = []
    lo, hi = head.tilt_limits
    for row, depression in enumerate(depressions_rad):
        tilt = min(hi, max(lo, head.tilt_sign * depression))
        if row == 0:
            order = first
        else:
            last = out[-1][0]
            order = sorted(range(len(pans)), key=lambda k: abs(pans[k] - last))
        out.extend((pans[k], tilt) for k in order)
    return out


def turn_offsets(robot: RobotModel, camera: str = "wide", overlap: float = 0.1) -> list[float]:
    """Body yaw offsets [rad] from the heading at the start of a search, each followed by a head scan,
    so that the scans together see all around: the head covers its pan range plus the field of view."""
    head = head_joints(robot, camera)
    coverage = (head.pan_limits[1] - head.pan_limits[0] + head.hfov_rad) * (1.0 - overlap)
    n = math.ceil(2.0 * math.pi / coverage - 1e-9)
    return [math.remainder(2.0 * math.pi * k / n, 2.0 * math.pi) for k in range(1, n)]


def head_trajectory(
    robot: RobotModel,
    q_start: np.ndarray,
    pan_rad: float,
    tilt_rad: float,
    camera: str = "wide",
    max_speed_rad_s: float = 1.0,
    dt_s: float = 0.005,
) -> np.ndarray:
    """(N, nq) configurations every ``dt_s`` moving the head from ``q_start`` to (pan, tilt) [rad].

    Minimum-jerk profile (peak speed 1.875 x mean speed) lasting just long enough to keep both joints
    under ``max_speed_rad_s``; every other coordinate stays at ``q_start``. Sample 0 is ``q_start``, as
    ``sim/execute`` expects. InvalidRequestError for a target outside the joint limits.
    """
    head = head_joints(robot, camera)
    q0 = robot.check_q(np.asarray(q_start, dtype=float))
    for name, value, (lo, hi) in (
        (head.pan, pan_rad, head.pan_limits),
        (head.tilt, tilt_rad, head.tilt_limits),
    ):
        if not lo - 1e-9 <= value <= hi + 1e-9:
            raise InvalidRequestError(f"{name} = {value:.3f} rad is outside its limits [{lo:.3f}, {hi:.3f}]")
    if not (max_speed_rad_s > 0 and dt_s > 0):
        raise InvalidRequestError("max_speed_rad_s and dt_s must be > 0")
    ip, it = robot.joint_index(head.pan).idx_q, robot.joint_index(head.tilt).idx_q
    delta = np.array([pan_rad - q0[ip], tilt_rad - q0[it]])
    duration = max(0.1, 1.875 * float(np.abs(delta).max()) / max_speed_rad_s)
    n = math.ceil(duration / dt_s) + 1
    s = np.linspace(0.0, 1.0, n)
    blend = smoothstep5(s)  # minimum jerk, zero velocity/acceleration at both ends
    q = np.repeat(q0[None, :], n, axis=0)
    q[:, ip] = q0[ip] + blend * delta[0]
    q[:, it] = q0[it] + blend * delta[1]
    return q
