"""Picking the bar up: the standing arm motion that brings both hands around a bar lying on its stands.

The set-up of the bar-carrying experiment ("Experiments with HRP-2 No. 14", `001_771c0ce3779b0683.txt`,
Figure 3 (a): the robot starts holding the bar). The sim's bar lies on two stands in front of the robot;
this motion moves the arms (the soles stay where they are and the CoM above the same floor point, so the
support polygon does not change) from the starting posture to a pre-grasp 8 cm behind the bar along each
hand's approach axis (the grasp frame's z axis, which points back to the wrist) and then onto the bar,
where the grippers close.

The hands approach from behind and above at ``approach_pitch_rad`` below the horizontal (fingers pointing
forward and down, the bar between the fingers, the closing axis across the bar); the first pitch of
:data:`APPROACH_PITCHES_RAD` that seeds a converging IK is used (the roll about the bar is then
left free). Both moves are straight lines of the grasp frames in task space (geodesic rotation) with
quintic timing, so the fingers stay behind the bar until the last 8 cm; the IK (soles, CoM and grippers
held > hands > rest posture) runs at every sample.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.bus.schemas.navigation import REASON_BAR_OUT_OF_REACH
from services.collision.carried import CarriedBar
from services.errors import InfeasibleError, InvalidRequestError
from services.ik import (
    ComPositionTask,
    FramePoseTask,
    HierarchicalSolver,
    JointLimitsTask,
    Level,
    PostureTask,
    run,
)
from services.navigation.carry import HandOnBarTask, bar_rotation
from services.walking.zmp_reference import smoothstep5

JOINT_MARGIN_RAD = 0.0
"""The grasp posture keeps every joint this far inside its limits [rad]."""
APPROACH_PITCHES_RAD = tuple(math.radians(d) for d in (35.0, 30.0, 40.0, 25.0, 45.0))


@dataclass(frozen=True, eq=False)
class PickupMotion:
    """The pick-up: ``q`` (n, nq) every ``dt_s`` [s] from the start to the grasp posture (pre-grasp at
    sample ``pregrasp_index``), the grasp posture ``q_grasp`` (nq), the approach pitch used [rad], and the
    largest hand pose error of the two IK solutions [m]."""

    q: np.ndarray
    dt_s: float
    pregrasp_index: int
    q_grasp: np.ndarray
    approach_pitch_rad: float
    ik_error_m: float


def _grasp_rotation(side: str, bar_axis: np.ndarray, pitch_rad: float) -> np.ndarray:
    """R_world_grasp: x along the bar (towards the robot's ``side``), z back to the wrist (behind and
    above the bar by ``pitch_rad``), y = z cross x."""
    R_bar = bar_rotation(bar_axis)
    x = R_bar[:, 0] if side == "left" else -R_bar[:, 0]
    ahead = -R_bar[:, 1]  # y_bar = z x x_bar: with x_bar to the robot's left, -y_bar is ahead of it
    z = -math.cos(pitch_rad) * ahead + math.sin(pitch_rad) * np.array([0.0, 0.0, 1.0])
    z = z - (z @ x) * x
    z /= np.linalg.norm(z)
    return np.column_stack([x, np.cross(z, x), z])


def _hold_and_posture(robot: object, q_rest: np.ndarray) -> tuple[list[Level], Level]:
    """The first levels (both soles where they are at ``q_rest``, the CoM above the same floor point, the
    grippers as they are: only the sim moves them; then every joint ``JOINT_MARGIN_RAD`` inside its
    limits) and the last one (rest posture ``q_rest``)."""
    model = robot.model  # type: ignore[attr-defined]
    data = robot.new_data()  # type: ignore[attr-defined]
    feet = tuple(
        FramePoseTask(
            model, robot.frames.sole(side), robot.sole_pose(q_rest, side, data), name=f"{side}_sole"
        )  # type: ignore[attr-defined]
        for side in ("left", "right")
    )
    com = ComPositionTask(model, robot.com(q_rest, data))  # type: ignore[attr-defined]
    grippers = [robot.gripper_joint(side) for side in ("left", "right")]  # type: ignore[attr-defined]
    hold = Level((*feet, com, PostureTask(model, q_rest, grippers, name="grippers")), name="feet_com")
    # keep off the joint limits: a walk starting with a joint on its limit has the IK's bound active at
    # every knot (slow QPs, jerky motion of that joint)
    limits = Level((JointLimitsTask(model, margin_rad=JOINT_MARGIN_RAD),), name="joint_limits")
    return [hold, limits], Level((PostureTask(model, q_rest),), name="posture", damping=1e-4, tol=math.inf)


def _levels(
    robot: object, q_rest: np.ndarray, targets: dict[str, pin.SE3]
) -> tuple[list[Level], dict[str, FramePoseTask]]:
    """Soles, CoM and grippers held as at ``q_rest`` > both grasp frames on ``targets`` > rest posture."""
    model = robot.model  # type: ignore[attr-defined]
    tasks = {
        side: FramePoseTask(
            model,
            getattr(robot.frames, f"{side}_grasp"),
            T,
            max_step=0.1,
            name=f"{side}_grasp",  # type: ignore[attr-defined]
        )
        for side, T in targets.items()
    }
    hold, posture = _hold_and_posture(robot, q_rest)
    return [*hold, Level(tuple(tasks.values()), name="hands"), posture], tasks


def _pose_error(robot: object, q: np.ndarray, targets: dict[str, pin.SE3]) -> float:
    data = robot.new_data()  # type: ignore[attr-defined]
    error = 0.0
    for side, T in targets.items():
        T_now = robot.frame_pose(q, getattr(robot.frames, f"{side}_grasp"), data)  # type: ignore[attr-defined]
        error = max(error, float(np.linalg.norm(pin.log6(T_now.actInv(T)).vector)))
    return error


def _solve_posture(
    robot: object,
    q_seed: np.ndarray,
    q_rest: np.ndarray,
    targets: dict[str, pin.SE3],
    solver: HierarchicalSolver,
) -> tuple[np.ndarray, float]:
    """The body reaches ``targets`` (grasp frame poses) with the soles and CoM held as at ``q_rest``."""
    levels, _ = _levels(robot, q_rest, targets)
    result = run(solver, levels, q_seed, max_iters=300, tol=1e-6)
    return result.q, _pose_error(robot, result.q, targets)


def _interpolate(T0: pin.SE3, T1: pin.SE3, s: float) -> pin.SE3:
    """Straight line for the position, geodesic for the rotation, at fraction ``s``."""
    R = T0.rotation @ pin.exp3(s * pin.log3(T0.rotation.T @ T1.rotation))
    return pin.SE3(R, (1.0 - s) * T0.translation + s * T1.translation)


def _track(
    robot: object,
    q_start: np.ndarray,
    q_rest: np.ndarray,
    start: dict[str, pin.SE3],
    goal: dict[str, pin.SE3],
    n: int,
    solver: HierarchicalSolver,
    iterations: int = 2,
) -> np.ndarray:
    """(n, nq): the grasp frames moved from ``start`` to ``goal`` poses in task space (quintic timing),
    the IK solved at every sample from the previous one."""
    levels, tasks = _levels(robot, q_rest, start)
    model = robot.model  # type: ignore[attr-defined]
    q = q_start.copy()
    out = np.empty((n, q.shape[0]))
    for k, s in enumerate(smoothstep5(np.arange(1, n + 1) / n)):
        for side, task in tasks.items():
            task.set_target(_interpolate(start[side], goal[side], float(s)))
        for _ in range(iterations):
            q = pin.integrate(model, q, solver.solve(levels, q))
        out[k] = q
    return out


@dataclass(frozen=True, eq=False)
class _Posture:
    """A candidate grasp: the approach pitch seeding it, the grasp and pre-grasp configurations and the
    grasp frames' poses there."""

    pitch_rad: float
    q_grasp: np.ndarray
    q_pregrasp: np.ndarray
    grasp: dict[str, pin.SE3]
    pregrasp: dict[str, pin.SE3]
    error: float


def _postures(
    robot: object,
    q_start: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    bar: CarriedBar,
    hand_spacing_m: float,
    approach_m: float,
    finger_gap_m: float,
    tolerance_m: float,
    solver: HierarchicalSolver,
    errors: list[float],
) -> Iterator[_Posture]:
    """Grasp postures from behind the bar, one per approach pitch that converges (rejected errors are
    appended to ``errors``)."""
    model = robot.model  # type: ignore[attr-defined]
    ahead = -bar_rotation(axis)[:, 1]
    held = {}
    points = {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        offset = robot.held_object_offset(side, bar.radius_m)  # type: ignore[attr-defined]
        # stop short of the fixed finger: closing pushes the bar the last few millimetres
        held[side] = offset - finger_gap_m * np.sign(offset[1]) * np.array([0.0, 1.0, 0.0])
        points[side] = centre + sign * 0.5 * hand_spacing_m * axis
    frames = {side: getattr(robot.frames, f"{side}_grasp") for side in ("left", "right")}  # type: ignore[attr-defined]
    hold, posture = _hold_and_posture(robot, q_start)
    on_bar = Level(
        tuple(HandOnBarTask(model, frames[s], held[s], points[s], axis, name=f"{s}_on_bar") for s in held),
        name="hands_on_bar",
    )
    data = robot.new_data()  # type: ignore[attr-defined]
    for pitch in APPROACH_PITCHES_RAD:
        # seed: the grasp at this approach pitch (exact or not); then the roll about the bar is let free
        seed_targets = {}
        for side in ("left", "right"):
            R = _grasp_rotation(side, axis, pitch)
            seed_targets[side] = pin.SE3(R, points[side] - R @ held[side])
        q_seed, _ = _solve_posture(robot, q_start, q_start, seed_targets, solver)
        result = run(solver, [*hold, on_bar, posture], q_seed, max_iters=300, tol=1e-6)
        error = float(result.residuals[len(hold)])
        grasp = {side: robot.frame_pose(result.q, frames[side], data) for side in ("left", "right")}  # type: ignore[attr-defined]
        from_behind = all(float(T.rotation[:, 2] @ ahead) < -0.2 for T in grasp.values())
        if error > tolerance_m or not from_behind:
            errors.append(error)
            continue
        pregrasp = {
            side: pin.SE3(T.rotation, T.translation + approach_m * T.rotation[:, 2])
            for side, T in grasp.items()
        }
        q_pre, err_p = _solve_posture(robot, result.q, q_start, pregrasp, solver)
        if err_p > tolerance_m:
            errors.append(err_p)
            continue
        yield _Posture(pitch, result.q, q_pre, grasp, pregrasp, max(error, err_p))


def _bar_line(robot: object, q_start: np.ndarray, bar_axis_world: np.ndarray) -> np.ndarray:
    """The bar's unit axis, pointing to the robot's left."""
    axis = np.asarray(bar_axis_world, dtype=float)
    axis = axis / np.linalg.norm(axis)
    T_base = robot.frame_pose(q_start, robot.frames.base)  # type: ignore[attr-defined]
    return -axis if axis @ T_base.rotation[:, 1] < 0.0 else axis


def _grasp_inputs(
    robot: object,
    q_start: np.ndarray,
    bar_centre_world_m: np.ndarray,
    bar_axis_world: np.ndarray,
    bar: CarriedBar | None,
    hand_spacing_m: float,
) -> tuple[CarriedBar, np.ndarray, np.ndarray, np.ndarray, HierarchicalSolver]:
    """The checked inputs of a grasp of the bar: (the bar, q_start, the bar's unit axis pointing to the
    robot's left, its centre [m] world, a solver for the robot); InvalidRequestError for a bad q_start
    or a hand spacing that does not fit the bar."""
    bar = bar or CarriedBar()
    q_start = robot.check_q(q_start)  # type: ignore[attr-defined]
    if not 0.1 <= hand_spacing_m <= bar.length_m - 0.1:
        raise InvalidRequestError(
            f"hand_spacing_m={hand_spacing_m} m must be within 0.1 m and the bar's length minus 0.1 m"
        )
    axis = _bar_line(robot, q_start, bar_axis_world)
    centre = np.asarray(bar_centre_world_m, dtype=float)
    return bar, q_start, axis, centre, HierarchicalSolver(robot.model)  # type: ignore[attr-defined]


def _out_of_reach(centre: np.ndarray, errors: list[float]) -> InfeasibleError:
    best = min(errors, default=math.inf)
    return InfeasibleError(
        f"no arm posture puts both hands on the bar at ({centre[0]:.2f}, {centre[1]:.2f}, {centre[2]:.2f}) m "
        f"with the feet still (best pose error {best:.3f}): bring the robot closer to the bar",
        {"reason": REASON_BAR_OUT_OF_REACH, "best_error": best},
    )


def bar_grasp_configuration(
    robot: object,
    q_start: np.ndarray,
    bar_centre_world_m: np.ndarray,
    bar_axis_world: np.ndarray,
    bar: CarriedBar | None = None,
    hand_spacing_m: float = 0.7,
    tolerance_m: float = 1e-3,
) -> np.ndarray:
    """The configuration (nq) of :func:`plan_bar_pickup`'s grasp, without the motion to it: both hands on
    the bar (against the fixed fingers), the soles and CoM as at ``q_start``."""
    bar, q_start, axis, centre, solver = _grasp_inputs(
        robot, q_start, bar_centre_world_m, bar_axis_world, bar, hand_spacing_m
    )
    errors: list[float] = []
    for posture in _postures(
        robot, q_start, centre, axis, bar, hand_spacing_m, 0.08, 0.0, tolerance_m, solver, errors
    ):
        return posture.q_grasp
    raise _out_of_reach(centre, errors)


def plan_bar_pickup(
    robot: object,
    q_start: np.ndarray,
    bar_centre_world_m: np.ndarray,
    bar_axis_world: np.ndarray,
    bar: CarriedBar | None = None,
    hand_spacing_m: float = 0.7,
    approach_m: float = 0.08,
    finger_gap_m: float = 0.006,
    max_joint_speed_rad_s: float = 0.6,
    dt_s: float = 0.005,
    tolerance_m: float = 1e-3,
) -> PickupMotion:
    """The arm motion from ``q_start`` to both hands on the bar (centre ``bar_centre_world_m`` [m], axis
    ``bar_axis_world``, horizontal), the hands ``hand_spacing_m`` [m] apart and centred on it, the bar
    ``finger_gap_m`` [m] short of each fixed finger (the closing finger pushes it there).

    InfeasibleError when no approach pitch puts both hands on the bar within ``tolerance_m`` (pose error,
    [m] and [rad] combined); InvalidRequestError for a spacing that does not fit the bar.
    """
    bar, q_start, axis, centre, solver = _grasp_inputs(
        robot, q_start, bar_centre_world_m, bar_axis_world, bar, hand_spacing_m
    )
    data = robot.new_data()  # type: ignore[attr-defined]
    frames = {side: getattr(robot.frames, f"{side}_grasp") for side in ("left", "right")}  # type: ignore[attr-defined]
    current = {side: robot.frame_pose(q_start, frames[side], data) for side in ("left", "right")}  # type: ignore[attr-defined]
    errors: list[float] = []
    for posture in _postures(
        robot,
        q_start,
        centre,
        axis,
        bar,
        hand_spacing_m,
        approach_m,
        finger_gap_m,
        tolerance_m,
        solver,
        errors,
    ):
        move = float(np.abs(posture.q_pregrasp[7:] - q_start[7:]).max())
        n_reach = max(round(1.5 / dt_s), math.ceil(1.875 * move / max_joint_speed_rad_s / dt_s))
        n_grasp = round(1.0 / dt_s)
        reach = _track(robot, q_start, q_start, current, posture.pregrasp, n_reach, solver)
        approach = _track(robot, reach[-1], q_start, posture.pregrasp, posture.grasp, n_grasp, solver)
        q = np.vstack([q_start[None], reach, approach])
        final_error = _pose_error(robot, q[-1], posture.grasp)
        if final_error > 10.0 * tolerance_m:
            errors.append(final_error)
            continue
        pitch_used = float(math.asin(max(-1.0, min(1.0, posture.grasp["left"].rotation[2, 2]))))
        return PickupMotion(q, dt_s, n_reach, q[-1].copy(), pitch_used, max(posture.error, final_error))
    raise _out_of_reach(centre, errors)
