"""A settle: both soles back flat on the ground and the body over them, from a measured configuration.

A motion stopped by a collision and played backward (a back-out) can leave a sole a few millimetres up
or tilted by a few degrees (measured 3 mm - 1.4 cm, 0.025 - 0.16 rad). Every planner wants both soles
flat to start from (footsteps, reaching, walking: 5 mm, 0.02 rad), so nothing could be planned from
there. The settle is the motion that brings the robot back to such a stance, quasi-statically:

1. the *anchor* sole is the one the robot stands on: the one whose lowest corner is nearer the ground
   (maybe rolled onto an edge of it), the flatter one when both touch (a step stopped mid-swing keeps
   its foot flat in the air: the lower sole, not the flatter, holds the robot); the motion starts at
   the measured configuration, base included, and every target is in the world frame, the ground at
   z = 0;
2. the other sole comes down flat onto the ground below it (its x, y and heading kept), the anchor
   sole and the CoM held where they are (the robot is at rest there: what holds it up holds it while
   the other foot comes down; while that sole is in the air, the balance is checked on the anchor
   sole alone);
3. the anchor sole turns flat below where it is, and the CoM moves over the middle of the two soles;
   a short hold.

A sole's way from its measured pose to flat is a screw motion (SE(3) interpolation), which turns a sole
resting on an edge roughly about that edge. Each stage is a quintic
(:func:`~services.model.ground.smoothstep5`) tracked by the prioritized IK of the walk
(:class:`~services.walking.wholebody.WholeBodyPlanner`'s model and solver: both soles > the CoM > waist
and chest upright > the measured posture), on knots splined to 5 ms as the walk is. The
multibody ZMP of the result (paper 001's dynamic balance check, Kajita 2003's ZMP from the centroidal
dynamics) must stay inside the support polygon of both soles laid flat where they come down.

Refusals: ``InvalidRequestError`` with reason ``already_settled`` when both soles are flat already
(within 1 mm and 0.005 rad); ``InfeasibleError`` with reason ``leaning`` when the CoM is outside both
feet laid flat: the robot is held up by something it touches, and no motion of the feet alone can
settle it. Pure: no bus here (``service.py`` is the adapter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from services.bus.schemas.walking import REASON_ALREADY_SETTLED, REASON_LEANING, REASON_OUT_OF_BOUNDS
from services.errors import InfeasibleError, InvalidRequestError
from services.ik import ComPositionTask, FrameOrientationTask, FramePoseTask, Level, PostureTask
from services.model.ground import (
    convex_hull_ccw,
    rectangles_overlap_depth,
    signed_distance,
    smoothstep5,
    sole_corners,
    sole_pose_of,
    yaw_of,
)
from services.walking.timing import DOUBLE, LEFT, RIGHT
from services.walking.two_stage import SupportSamples
from services.walking.wholebody import WholeBodyOptions, WholeBodyPlanner, _spline_configurations

#: Both soles within this of the ground [m] and of horizontal [rad]: nothing to settle.
SETTLED_M = 0.001
SETTLED_RAD = 0.005
#: A sole whose lowest corner is this far above the ground [m] is in the air: it supports nothing while
#: it comes down (the anchor's lone sole is then the support polygon).
AIRBORNE_M = 0.002
#: Durations of the stages [s]: the CoM's shift with the anchor sole's flattening, the other sole's
#: lowering, the final hold.
SHIFT_S = 1.5
LOWER_S = 1.0
HOLD_S = 0.3
#: Samples between two IK knots, and Gauss-Newton steps per knot.
KNOT_STRIDE = 8
ITERATIONS = 3
DT_S = 0.005


@dataclass(frozen=True)
class SettleMotion:
    """The settle on a ``dt_s`` grid (n samples): ``q`` (n, nq), the CoM reference ``com_ref_m`` and the
    CoM of ``q`` (n, 3) [m], its multibody ZMP (n, 2) [m] and signed distance to the support polygon
    (n,) [m] (< 0 inside), the sole targets (n, 4) = x, y, z, yaw, the support ``phase`` (n,) (0 both
    soles, 1 the left, 2 the right), the ``anchor`` side, the other sole's height [m] and tilt [rad]
    before, and the largest sole tracking error [m]."""

    dt_s: float
    times_s: np.ndarray
    q: np.ndarray
    com_m: np.ndarray
    com_ref_m: np.ndarray
    zmp_m: np.ndarray
    zmp_distance_m: np.ndarray
    left_sole: np.ndarray
    right_sole: np.ndarray
    phase: np.ndarray
    anchor: str
    lowered_height_m: float
    lowered_tilt_rad: float
    max_sole_error_m: float


def _tilt(T: pin.SE3) -> float:
    """Angle [rad] between a frame's z axis and the vertical."""
    return math.acos(max(-1.0, min(1.0, float(T.rotation[2, 2]))))


def _flat(T: pin.SE3) -> pin.SE3:
    """The frame laid flat on the ground z = 0 below its origin, its heading kept."""
    yaw = yaw_of(T.rotation)
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([T.translation[0], T.translation[1], 0.0]))


def _upright(R: np.ndarray) -> np.ndarray:
    """The rotation with the heading of ``R``, roll and pitch zero."""
    return pin.rpy.rpyToMatrix(0.0, 0.0, yaw_of(R))


def _lowest_corner_z(T: pin.SE3, length_m: float, width_m: float) -> float:
    """Height [m] of the lowest corner of a sole rectangle (``length_m`` x ``width_m`` centred on its frame
    ``T``): about 0 for a sole touching the ground, flat or rolled onto an edge."""
    local = np.array([[sx * length_m / 2, sy * width_m / 2, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    return float(np.min(T.translation[2] + local @ T.rotation[2, :]))


def anchor_side(soles: dict[str, pin.SE3], length_m: float, width_m: float) -> str:
    """The side of the sole the robot stands on (module docstring, 1.), of the sole frames ``soles``
    (world) and the sole rectangle's size [m]: the one whose lowest corner is on the ground (to the
    millimetre), then the flatter (a walk keeps its raised foot flat: flatness alone picks it)."""

    def key(side: str) -> tuple[int, float]:
        T = soles[side]
        return round(1e3 * max(_lowest_corner_z(T, length_m, width_m), 0.0)), _tilt(T)

    return min(("left", "right"), key=key)


def _row(T: pin.SE3) -> np.ndarray:
    """(x, y, z, yaw) of a frame."""
    return np.array([*T.translation, yaw_of(T.rotation)])


def settle_motion(robot: Any, q_measured: np.ndarray, *, zmp_margin_m: float = 0.01) -> SettleMotion:
    """The settle of a ``services.model`` robot from ``q_measured`` (nq,) (module docstring).

    Raises:
        InvalidRequestError: ``details.reason`` ``already_settled``.
        InfeasibleError: ``details.reason`` ``leaning`` (the robot is held by something), or
            ``out_of_bounds`` (the lowered sole would land on the other one, a sole out of the leg's
            reach, the multibody ZMP outside the support).
    """
    q = robot.check_q(q_measured, "q_start")
    data = robot.new_data()
    soles = {side: robot.sole_pose(q, side, data) for side in ("left", "right")}
    state = {side: (abs(float(T.translation[2])), _tilt(T)) for side, T in soles.items()}
    described = ", ".join(
        f"{side} sole {1e3 * T.translation[2]:.1f} mm up, tilted {_tilt(T):.3f} rad"
        for side, T in soles.items()
    )
    if all(h <= SETTLED_M and t <= SETTLED_RAD for h, t in state.values()):
        raise InvalidRequestError(
            f"both soles are flat on the ground already ({described}): nothing to settle",
            {"reason": REASON_ALREADY_SETTLED},
        )
    length, width = (float(v) for v in robot.sole_size_m)
    lowest = {side: _lowest_corner_z(T, length, width) for side, T in soles.items()}
    anchor = anchor_side(soles, length, width)
    other = "right" if anchor == "left" else "left"
    q0 = q
    flat = {side: _flat(T) for side, T in soles.items()}
    rect = {side: sole_corners(sole_pose_of(T), length, width) for side, T in flat.items()}
    if rectangles_overlap_depth(rect[anchor], rect[other]) > 0.0:
        raise InfeasibleError(
            f"the {other} sole would come down on the {anchor} one ({described})",
            {"reason": REASON_OUT_OF_BOUNDS},
        )
    com0 = robot.com(q0, data)
    hull = convex_hull_ccw(np.vstack([rect[anchor], rect[other]]))
    outside = float(signed_distance(com0[:2], hull)[0])
    if outside > 0.0:
        raise InfeasibleError(
            f"the centre of mass is {1e3 * outside:.0f} mm outside the feet ({described}): the robot "
            "leans on something it touches, no motion of the feet can settle it; free it first",
            {"reason": REASON_LEANING},
        )
    # the stages' targets on the 5 ms grid: each sole from its measured pose to flat below it (a screw
    # motion: a sole resting on an edge turns about it roughly), the other one first, then the anchor
    # with the CoM to the middle
    mid_xy = 0.5 * (flat[anchor].translation[:2] + flat[other].translation[:2])
    n_lower, n_centre, n_hold = (round(s / DT_S) for s in (LOWER_S, SHIFT_S, HOLD_S))
    n = 1 + n_lower + n_centre + n_hold
    com_ref = np.tile(com0, (n, 1))
    phase = np.full(n, DOUBLE, dtype=np.int8)
    if lowest[other] > AIRBORNE_M:  # the other foot in the air until it lands: the anchor alone holds
        phase[: 1 + n_lower] = LEFT if anchor == "left" else RIGHT
    sole_T: dict[str, list[pin.SE3]] = {anchor: [soles[anchor]] * n, other: [soles[other]] * n}
    for side, start, m in ((other, 1, n_lower), (anchor, 1 + n_lower, n_centre)):
        screw = pin.log6(soles[side].inverse() * flat[side]).vector
        s = smoothstep5(np.arange(1, m + 1) / m)
        sole_T[side][start : start + m] = [soles[side] * pin.exp6(si * screw) for si in s]
        sole_T[side][start + m :] = [flat[side]] * (n - start - m)
    s = smoothstep5(np.arange(1, n_centre + 1) / n_centre)
    centre = slice(1 + n_lower, 1 + n_lower + n_centre)
    com_ref[centre, :2] = com0[:2] + s[:, None] * (mid_xy - com0[:2])
    com_ref[1 + n_lower + n_centre :, :2] = mid_xy
    soles_rows = {side: np.array([_row(T) for T in poses]) for side, poses in sole_T.items()}
    # IK on the knots (the walk's model and solver), splined to every sample
    planner = WholeBodyPlanner(robot, WholeBodyOptions())
    model = planner.model
    frames = robot.frames
    feet = {
        side: FramePoseTask(model, frames.sole(side), pin.SE3.Identity(), name=f"{side}_sole")
        for side in ("left", "right")
    }
    com = ComPositionTask(model, com0)
    R_waist0 = robot.frame_pose(q0, frames.base, data).rotation
    R_chest0 = robot.frame_pose(q0, frames.torso, data).rotation
    waist = FrameOrientationTask(model, frames.base, R_waist0, name="waist")
    chest = FrameOrientationTask(model, frames.torso, R_chest0, name="chest")
    levels = [
        Level((feet["left"], feet["right"]), name="feet"),
        Level((com,), name="com"),
        Level((waist, chest), name="waist_chest"),
        Level((PostureTask(model, planner.reduce_q(q0)),), name="posture", damping=1e-6),
    ]
    knots = list(range(0, n, KNOT_STRIDE))
    if knots[-1] != n - 1:
        knots.append(n - 1)
    upright = smoothstep5(np.asarray(knots, dtype=float) / (n - 1))
    dR_waist = pin.log3(R_waist0.T @ _upright(R_waist0))
    dR_chest = pin.log3(R_chest0.T @ _upright(R_chest0))
    x = planner.reduce_q(q0)
    Q = np.empty((len(knots), model.nq))
    Q[0] = x
    for i, kk in enumerate(knots[1:], start=1):
        for side in ("left", "right"):
            feet[side].set_target(sole_T[side][kk])
        com.set_target(com_ref[kk])
        waist.set_target(R_waist0 @ pin.exp3(upright[i] * dR_waist))
        chest.set_target(R_chest0 @ pin.exp3(upright[i] * dR_chest))
        for _ in range(ITERATIONS):
            x = pin.integrate(model, x, planner.solver.solve(levels, x))
        Q[i] = x
    times = DT_S * np.arange(n)
    qs = planner.expand_q(_spline_configurations(times[knots], Q, times), q0)
    qs[0] = q0  # the motion starts exactly where the robot is (its measured base and joints)
    np.clip(qs[:, 7:], robot.q_lower[7:], robot.q_upper[7:], out=qs[:, 7:])
    left_rows, right_rows = soles_rows["left"], soles_rows["right"]
    sole_error = _sole_error(robot, qs, {"left": left_rows, "right": right_rows})
    if sole_error > 0.002:
        raise InfeasibleError(
            f"the soles miss their settled poses by {1e3 * sole_error:.1f} mm ({described}): out of the "
            "legs' reach",
            {"reason": REASON_OUT_OF_BOUNDS, "error_m": sole_error},
        )
    support = SupportSamples(phase, left_rows, right_rows, (length, width), DT_S, com_ref[:, :2])
    mb, dist = support.zmp_distance(robot.model, qs)
    worst = int(np.argmax(dist))
    if dist[worst] > -zmp_margin_m:
        raise InfeasibleError(
            f"the multibody ZMP comes {1e3 * (dist[worst] + zmp_margin_m):.1f} mm too near the edge of the "
            f"support (margin {1e3 * zmp_margin_m:.0f} mm) at t={times[worst]:.2f} s of the settle "
            f"({described})",
            {"reason": REASON_OUT_OF_BOUNDS, "time_s": float(times[worst])},
        )
    return SettleMotion(
        dt_s=DT_S,
        times_s=times,
        q=qs,
        com_m=mb.com_m,
        com_ref_m=com_ref,
        zmp_m=mb.zmp_m,
        zmp_distance_m=dist,
        left_sole=left_rows,
        right_sole=right_rows,
        phase=phase,
        anchor=anchor,
        lowered_height_m=float(soles[other].translation[2]),
        lowered_tilt_rad=state[other][1],
        max_sole_error_m=sole_error,
    )


def _sole_error(robot: Any, qs: np.ndarray, targets: dict[str, np.ndarray]) -> float:
    """Largest distance [m] of the soles of ``qs`` (n, nq) from their target rows (n, 4)."""
    data = robot.new_data()
    ids = {side: robot.frame_id(robot.frames.sole(side)) for side in targets}
    err = 0.0
    for k in range(qs.shape[0]):
        pin.forwardKinematics(robot.model, data, qs[k])
        for side, fid in ids.items():
            p = pin.updateFramePlacement(robot.model, data, fid).translation
            err = max(err, float(np.abs(p - targets[side][k, :3]).max()))
    return err
