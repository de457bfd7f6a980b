"""The robot's body as the supervisor uses it: proprioception, trajectory execution, head, grippers.

Everything goes through ``sim`` (the only component that executes, CONVENTIONS §1): the state is the
robot's own proprioception (``sim/state``: joints, base pose, what each hand holds), planners'
trajectories are played by ``sim/execute``, and short head motions are made here (a smooth joint
trajectory from the current configuration). Object positions never come from here.

Long trajectories are sent in chunks of about one second of sim time: the supervisor reports progress
between chunks and honours "stop" there (the sim freezes physics between requests, so consecutive
chunks play as one trajectory; each chunk starts at the previous chunk's last sample).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from services.bus.schemas import sim as sim_msg
from services.bus.schemas.common import START_SOLE_MAX_HEIGHT_M, START_SOLE_MAX_TILT_RAD
from services.errors import CollisionError, FellError, InternalError, StoppedError, WorldOutcomeError
from supervisor.calls import ServiceCaller
from supervisor.robot import Robot

#: Samples of one chunk of an executed trajectory (1 s at 5 ms).
CHUNK_SAMPLES = 200
#: Head pan / tilt joints of the models (pan positive = left, tilt positive = down) [rad].
HEAD_SPEED_RAD_S = 1.5
EXECUTE_TIMEOUT_S = 60.0
#: Plan from the last commanded configuration when every joint is within this of it [rad].
PLAN_FROM_COMMAND_RAD = 0.05
#: Backing out of a stopped motion goes back at least this far [s], then on to an instant both soles
#: were on the floor (within ``FLAT_SOLE_M`` [m]: the planners want them within 5 mm).
BACK_OUT_MIN_S = 0.5
FLAT_SOLE_M = 0.004
#: The back-out's last this much of path [s] is played slowing down to a stop (in twice the time).
BACK_OUT_EASE_S = 0.4
#: The planners start only from soles within 5 mm of the ground and 0.02 rad of horizontal
#: (footsteps, reaching, navigation: their ``q_start`` checks; one pair in the schemas).
PLANNERS_FLAT_M = START_SOLE_MAX_HEIGHT_M
PLANNERS_FLAT_RAD = START_SOLE_MAX_TILT_RAD

Progress = Callable[[str], None]


@dataclass(frozen=True)
class Executed:
    """What an execution did: sim time spent [s], the final configuration, the last reply, and whether
    it stopped early on touching the object it was told to expect (``touch``)."""

    duration_s: float
    q: np.ndarray
    reply: sim_msg.ExecuteReply
    touched: bool = False


@dataclass(frozen=True)
class Interrupted:
    """The part of a trajectory played before a collision stopped it: ``q`` (M, nq) every ``dt_s``,
    with the contacts it was allowed, ``what`` it was for and the objects it touched."""

    q: np.ndarray
    dt_s: float
    allowed_contacts: tuple[str, ...]
    what: str
    touched: tuple[str, ...]


class Body:
    """Proprioception and motion of the simulated robot through ``sim``."""

    def __init__(self, bus: ServiceCaller, stop: threading.Event | None = None) -> None:
        self.bus = bus
        self.stop = stop or threading.Event()
        self.robot = Robot(bus)  # facts and kinematics from sim/robot_info, sim/kinematics
        self._commanded: np.ndarray | None = None  # last sample of the last completed trajectory
        self.interrupted: Interrupted | None = None  # the last motion a collision stopped, until backed out

    # State -----------------------------------------------------------------------------------------
    def state(self) -> sim_msg.StateReply:
        return self.bus.call(sim_msg.STATE, sim_msg.StateRequest(), 10.0)

    def q(self) -> np.ndarray:
        state = self.state()
        if state.fallen:
            raise FellError("the robot is on the ground: reset the sim (`humanoid fetch` does)")
        return np.asarray(state.q, dtype=float)

    def plan_q(self) -> np.ndarray:
        """The configuration to plan from: the last commanded one (the end of the trajectory just played)
        placed standing at the measured mid-feet pose, when the joints are where it commanded them; else
        the measured one.

        Planners want both soles flat on the ground; a measured configuration of a robot leaning to
        reach is a few mrad off (a sole tilted by 0.022 rad was refused by reaching), the commanded one is
        flat by construction. The sim accepts either as a trajectory's first sample (within 0.2 rad).
        """
        q = self.q()
        commanded = self._commanded
        if commanded is None:
            return q
        robot = self.robot
        grippers = [robot.gripper_index(side) for side in ("left", "right")]
        body = np.ones(robot.nq, dtype=bool)
        body[:7] = False
        body[grippers] = False  # they move with sim/gripper, not with trajectories
        if float(np.max(np.abs(commanded[body] - q[body]))) > PLAN_FROM_COMMAND_RAD:
            return q
        x, y, yaw = robot.mid_feet_pose(q)
        planned = np.array(robot.place_on_ground(commanded, x, y, yaw), dtype=float)
        planned[grippers] = q[grippers]
        return planned

    def held(self) -> dict[str, str]:
        return dict(self.state().held)

    def base_xy_yaw(self, q: np.ndarray | None = None) -> tuple[float, float, float]:
        """Mid-feet pose on the ground (x [m], y [m], yaw [rad]) at ``q`` (default: now)."""
        return self.robot.mid_feet_pose(self.q() if q is None else q)

    # Execution -------------------------------------------------------------------------------------
    def execute(
        self,
        Q: np.ndarray,
        *,
        what: str,
        dt_s: float = 0.005,
        allowed_contacts: Sequence[str] = (),
        progress: Progress | None = None,
        hold_s: float = 0.0,
        touch: str = "",
        leaving: Sequence[str] = (),
        supports: Sequence[str] = (),
        effort_scale: Mapping[str, float] | None = None,
    ) -> Executed:
        """Play the (N, nq) trajectory ``Q`` in chunks; FellError | CollisionError | StoppedError.
        ``effort_scale``: joints played with a fraction of their effort limits (sim/execute's).

        ``touch``: an object the motion is expected to bump into (a guarded move: lowering a held object
        onto a table of uncertain height); stopping on contacts with it only is a success with
        ``touched`` set, as a force sensor in the wrist would tell. ``leaving``: objects touched at the
        start that the motion moves away from (``sim/execute``'s ``leaving``); ``supports``: objects any link
        may touch (a multi-contact motion's supports). A collision stop keeps
        the executed part in :attr:`interrupted` (see :meth:`back_out`).
        """
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[0] < 2:
            raise InternalError(f"{what}: a trajectory needs (N >= 2, nq) samples, got {Q.shape}")
        total = (Q.shape[0] - 1) * dt_s
        self.interrupted = None  # a new motion: the last stopped one is not undone any more
        spent = 0.0
        start = 0
        reply: sim_msg.ExecuteReply | None = None
        self._commanded = None
        while start < Q.shape[0] - 1:
            if self.stop.is_set():
                raise StoppedError(f"{what}: stopped by the operator after {spent:.1f} s")
            end = min(Q.shape[0], start + CHUNK_SAMPLES + 1)
            last = end == Q.shape[0]
            request = sim_msg.ExecuteRequest(
                q=np.ascontiguousarray(Q[start:end]),
                dt_s=dt_s,
                allowed_contacts=list(allowed_contacts),
                hold_s=hold_s if last else 0.0,
                leaving=list(leaving),
                supports=list(supports),
                effort_scale=dict(effort_scale or {}),
            )
            reply = self.bus.call(sim_msg.EXECUTE, request, EXECUTE_TIMEOUT_S)
            spent += reply.duration_s
            if reply.outcome == "collision" and touch and all(c.other == touch for c in reply.collisions):
                return Executed(spent, np.asarray(reply.q, dtype=float), reply, touched=True)
            if reply.outcome != "completed":
                if reply.outcome == "collision":
                    self.interrupted = Interrupted(
                        Q[: start + max(1, reply.samples_executed)].copy(),
                        dt_s,
                        tuple(allowed_contacts),
                        what,
                        tuple(sorted({c.other for c in reply.collisions})),
                    )
                raise self._failure(what, reply, spent, total)
            if progress is not None and not last:
                progress(f"{what}: {spent:.1f} of {total:.1f} s")
            start = end - 1
        assert reply is not None
        self._commanded = Q[-1].copy()
        return Executed(spent, np.asarray(reply.q, dtype=float), reply)

    def standing(self, q: np.ndarray | None = None) -> bool:
        """Whether both soles are on the floor (within ``FLAT_SOLE_M``) at ``q`` (default: now)."""
        q = self.q() if q is None else q
        return bool(np.all(np.abs(self.robot.sole_heights(q)) < FLAT_SOLE_M))

    def soles(self, q: np.ndarray | None = None) -> dict[str, tuple[float, float]]:
        """Each sole's height [m] and tilt from horizontal [rad] at ``q`` (default: now)."""
        q = self.q() if q is None else q
        robot = self.robot
        out = {}
        for side in ("left", "right"):
            pose = robot.frame_pose(q, robot.info.frames[f"{side}_sole"])
            out[side] = (float(pose.translation[2]), math.acos(min(1.0, float(pose.rotation[2, 2]))))
        return out

    def plannable(self, q: np.ndarray | None = None) -> bool:
        """Whether the planners accept ``q`` (default: now) as a start: both soles within
        ``PLANNERS_FLAT_M`` of the ground and ``PLANNERS_FLAT_RAD`` of horizontal."""
        return all(
            abs(z) <= PLANNERS_FLAT_M and tilt <= PLANNERS_FLAT_RAD for z, tilt in self.soles(q).values()
        )

    def back_out(self, progress: Progress | None = None) -> float:
        """Undo the end of the motion a collision stopped: play its executed part backward (the same
        path, time reversed: the CoM accelerations, hence the ZMP, are those of the planned motion) for at
        least ``BACK_OUT_MIN_S``, on to the last instant both soles were on the floor. A robot stopped
        mid-step holds a foot in the air, where no planner can start from. Its last ``BACK_OUT_EASE_S``
        of path are played slowing down to a stop (:func:`_ease_out`): that instant of a walk has the
        CoM moving, and a robot stopped there abruptly swayed on, so that the settle planned from a
        snapshot of it ended tilted or fell (box_near). Returns the time played [s] (0 when nothing
        was interrupted)."""
        interrupted, self.interrupted = self.interrupted, None
        if interrupted is None or interrupted.q.shape[0] < 2:
            return 0.0
        Q = interrupted.q
        last = Q.shape[0] - 1
        k = max(0, last - round(BACK_OUT_MIN_S / interrupted.dt_s))
        flat = np.all(np.abs(self.robot.sole_heights(Q[: k + 1])) < FLAT_SOLE_M, axis=1)
        while k > 0 and not flat[k]:
            k -= 1
        what = f"back out of {interrupted.what} ({', '.join(interrupted.touched)})"
        if progress is not None:
            progress(f"{what}: {(last - k) * interrupted.dt_s:.1f} s of it backward")
        done = self.execute(
            _ease_out(Q[k:][::-1], round(BACK_OUT_EASE_S / interrupted.dt_s)),
            what=what,
            dt_s=interrupted.dt_s,
            allowed_contacts=interrupted.allowed_contacts,
            leaving=interrupted.touched,
        )
        return done.duration_s

    @staticmethod
    def _failure(what: str, reply: sim_msg.ExecuteReply, spent: float, total: float) -> WorldOutcomeError:
        details = {
            "outcome": reply.outcome,
            "at_s": spent,
            "of_s": total,
            "collisions": list(reply.collisions),  # sim_msg.Contact structs
            "tracking_error_rad": reply.tracking_error_rad,
        }
        if reply.outcome == "fell":
            return FellError(f"{what}: the robot fell after {spent:.1f} s: {reply.message}", details)
        return CollisionError(
            f"{what}: stopped by a collision after {spent:.1f} of {total:.1f} s: {reply.message}",
            details,
        )

    def move_joints(
        self,
        targets: Mapping[str, float],
        *,
        what: str,
        speed_rad_s: float = HEAD_SPEED_RAD_S,
        q: np.ndarray | None = None,
    ) -> Executed | None:
        """Move the named joints to ``targets`` [rad] with a quintic profile, the others held; None if
        already there."""
        q0 = self.q() if q is None else np.asarray(q, dtype=float)
        robot = self.robot
        q1 = q0.copy()
        for name, value in targets.items():
            i = robot.index(name)
            q1[i] = float(np.clip(value, robot.q_lower[i], robot.q_upper[i]))
        travel = float(np.max(np.abs(q1 - q0))) if q1.size else 0.0
        if travel < 1e-3:
            return None
        duration = max(0.3, 1.875 * travel / speed_rad_s)  # quintic peak speed = 1.875 travel / T
        n = math.ceil(duration / 0.005) + 1
        tau = np.linspace(0.0, 1.0, n)[:, None]
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        return self.execute(q0[None, :] + s * (q1 - q0)[None, :], what=what)

    def straighten(self, *, what: str = "stand up straight", tolerance_rad: float = 0.05) -> Executed | None:
        """Bring the chest joints back to the half-sitting posture (slowly, everything else held).

        Reaching leans the chest toward the target; the walking planner keeps the waist and chest
        upright from its first sample, so a walk planned from a leaning posture would start with a jump
        of the chest (its multibody ZMP leaves the support polygon at t = 0). None if already straight.
        """
        q = self.q()
        robot = self.robot
        half_sitting = robot.q_half_sitting
        targets = {n: float(half_sitting[robot.index(n)]) for n in robot.info.chest_joints}
        if all(abs(q[robot.index(n)] - v) < tolerance_rad for n, v in targets.items()):
            return None
        return self.move_joints(targets, what=what, speed_rad_s=0.5, q=q)

    # Head --------------------------------------------------------------------------------------------
    def head_joints(self) -> tuple[str, str]:
        """(pan, tilt) joint names of the robot (perception/look_around)."""
        head = self.robot.head
        return head.head_pan_joint, head.head_tilt_joint

    def head_angles(self, q: np.ndarray) -> tuple[float, float]:
        pan, tilt = self.head_joints()
        return float(q[self.robot.index(pan)]), float(q[self.robot.index(tilt)])

    def head_limits(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((pan min, pan max), (tilt min, tilt max)) [rad]."""
        head = self.robot.head
        (pan_lo, pan_hi), (tilt_lo, tilt_hi) = head.pan_limits_rad, head.tilt_limits_rad
        return (float(pan_lo), float(pan_hi)), (float(tilt_lo), float(tilt_hi))

    def move_head(self, pan_rad: float, tilt_rad: float, *, what: str = "head") -> Executed | None:
        pan, tilt = self.head_joints()
        return self.move_joints({pan: pan_rad, tilt: tilt_rad}, what=what)

    def head_angles_towards(self, q: np.ndarray, point_world: Sequence[float]) -> tuple[float, float]:
        """Pan and tilt [rad] that point the gaze axis at ``point_world`` [m] from configuration ``q``.

        Two fixed-point passes: the gaze frame moves a little with the head joints (neck offset).
        """
        robot = self.robot
        pan_name, tilt_name = self.head_joints()
        i_pan, i_tilt = robot.index(pan_name), robot.index(tilt_name)
        q = np.asarray(q, dtype=float).copy()
        target = np.asarray(point_world, dtype=float)
        (pan_lo, pan_hi), (tilt_lo, tilt_hi) = self.head_limits()
        for _ in range(3):
            T_world_gaze = robot.frame_pose(q, robot.info.frames["gaze"])
            d = T_world_gaze.rotation.T @ (target - T_world_gaze.translation)  # in the gaze frame
            pan = q[i_pan] + math.atan2(d[1], d[0])
            tilt = q[i_tilt] - self.robot.head.tilt_sign * math.atan2(d[2], math.hypot(d[0], d[1]))
            q[i_pan] = float(np.clip(pan, pan_lo, pan_hi))
            q[i_tilt] = float(np.clip(tilt, tilt_lo, tilt_hi))
        return float(q[i_pan]), float(q[i_tilt])

    # Grippers ----------------------------------------------------------------------------------------
    def gripper(self, side: str, action: str) -> sim_msg.GripperReply:
        return self.bus.call(sim_msg.GRIPPER, sim_msg.GripperRequest(side=side, action=action), 15.0)


def _ease_out(Q: np.ndarray, n: int) -> np.ndarray:
    """The (M, nq) path ``Q`` (one sample per period) with its last ``n`` samples played slowing down
    linearly from full speed to a stop, in 2 n periods: the sample index advances by 1 - t / (2 n) per
    period (t periods into the slowing part), configurations linearly interpolated between samples (the
    base quaternion renormalized). The path is unchanged; only its timing at the end."""
    M = Q.shape[0]
    n = min(n, M - 1)
    if n < 2:
        return Q
    t = np.arange(1, 2 * n + 1, dtype=float)
    u = (M - 1 - n) + t - t * t / (4.0 * n)  # integral of the speed 1 - t / (2 n)
    i = np.minimum(np.floor(u).astype(int), M - 2)
    a = (u - i)[:, None]
    tail = (1.0 - a) * Q[i] + a * Q[i + 1]
    tail[:, 3:7] /= np.linalg.norm(tail[:, 3:7], axis=1, keepdims=True)
    return np.vstack([Q[: M - n], tail])
