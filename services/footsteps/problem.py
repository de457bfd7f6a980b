"""The prioritized IK problem on a virtual chain: constraints of sections 3.2-3.3 at the top priority,
then the request's tasks in its priority order (section 4), then (with an initial guess of the number
of steps) the footprints held at their initial place with decreasing priority (section 5.1).
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np
import pinocchio as pin

from services.footsteps.arm_obstacles import arm_obstacle_tasks
from services.footsteps.chain import VirtualChain, footprint_frame
from services.footsteps.constraints import (
    FootprintDisksTask,
    FrontFootHoldTask,
    FrontRelativePose,
    FrontStepBoundsTask,
    NonOverlapTask,
    RootSoleOnFootprintTask,
)
from services.footsteps.geometry import relative_pose, se3_of
from services.footsteps.hand_floor import hand_floor_task
from services.footsteps.request import FootstepPlanRequest, FootstepTask
from services.ik.level import Level
from services.ik.task import Task
from services.ik.tasks.com_support_polygon import ComSupportPolygonTask
from services.ik.tasks.feet_flat import FeetFlatTask
from services.ik.tasks.frame_orientation import FrameOrientationTask
from services.ik.tasks.frame_pose import FramePoseTask
from services.ik.tasks.frame_position import FramePositionTask
from services.ik.tasks.gaze import GazeTask
from services.ik.tasks.posture import PostureTask
from services.ik.tasks.self_collision import SelfCollisionTask
from services.model import RobotModel

GAZE_AXIS_IN_FRAME = (1.0, 0.0, 0.0)  # the robot's ``gaze`` frame looks along its x axis
SELF_COLLISION_CACHE_SIZE = 64  # self-collision tasks kept (see self_collision_task)
_self_collision: OrderedDict[tuple, tuple[RobotModel, pin.Model, SelfCollisionTask]] = OrderedDict()
_self_collision_lock = threading.Lock()


def chain_q_rest(chain: VirtualChain, q_rest_robot: np.ndarray) -> np.ndarray:
    """A q~ whose robot part is ``q_rest_robot`` (chain part zero): the reference of eq. (14)."""
    q = np.zeros(chain.model.nq)
    q[chain.robot_slice()] = q_rest_robot
    return q


def robot_rest(robot: RobotModel, task: FootstepTask | None) -> np.ndarray:
    """q_rest of eq. (14) for ``robot`` (the task's, else the half-sitting)."""
    if task is not None and task.q_rest is not None:
        return np.asarray(task.q_rest, dtype=float)
    return np.array(robot.q_half_sitting)


def constraint_tasks(
    chain: VirtualChain, request: FootstepPlanRequest, front: FrontRelativePose | None = None
) -> list[Task]:
    """Level 0: the permanent constraints of sections 3.2-3.3 on the chain with its current number of
    steps (p = 0: the front foot also held at its initial sole). ``front``: the front sole's pose in
    F_{p-1}, shared with the other tasks that read it."""
    robot, model, opts = chain.robot, chain.model, request.options
    gain = opts.gain
    front = front or FrontRelativePose(chain)
    tasks: list[Task] = [RootSoleOnFootprintTask(chain, gain=gain)]
    if chain.n_steps == 0:
        tasks.append(
            FramePoseTask(
                model,
                chain.front_sole_frame,
                chain.T_root_world * se3_of(chain.start.of(chain.front_side)),
                gain=gain,
                name="front_foot_fixed",
            )
        )
    else:
        # "setting the vertical position of the front foot to that of the ground and authorizing its
        # rotation around the vertical" (section 3.2)
        tasks.append(FeetFlatTask(model, [chain.front_sole_frame], gain=gain, name="front_foot_flat"))
    # eq. (11): CoM projection inside the final support polygon (both soles of the robot).
    tasks.append(
        ComSupportPolygonTask(
            model,
            opts.com_margin_m,
            sole_frames=(robot.frames.left_sole, robot.frames.right_sole),
            sole_size_m=robot.sole_size_m,
            gain=gain,
        )
    )
    if chain.n_steps >= 1:
        tasks.append(FrontStepBoundsTask(chain, gain=gain, front=front))
        tasks.append(NonOverlapTask(chain, robot.sole_size_m, opts.overlap_margin_m, gain=gain, front=front))
        if request.disks:
            tasks.append(
                FootprintDisksTask(
                    chain,
                    robot.sole_size_m,
                    [chain.model_point((d.x_m, d.y_m)) for d in request.disks],
                    [d.radius_m for d in request.disks],
                    margin_m=opts.disk_margin_m,
                    gain=gain,
                )
            )
    if opts.self_collision and robot.collision_pairs:
        tasks.append(self_collision_task(chain, opts.collision_margin_m, gain))
    if opts.hand_floor:
        ground_z = float(chain.model_point(np.zeros(3))[2])
        tasks.append(hand_floor_task(robot, model, opts.hand_floor_margin_m, ground_z, gain))
    tasks.append(grippers_held(chain, request, gain))
    tasks.extend(arm_obstacle_tasks(chain, request))  # the arm out of the hand obstacles (eqs. 12-13)
    return tasks


def grippers_held(chain: VirtualChain, request: FootstepPlanRequest, gain: float) -> PostureTask:
    """The grippers at their start value, an equality: they are not part of the IK (the paper's HRP-2
    model has 28 degrees of freedom, its 30 without the two grippers, §4.1). Free, the IK closed the
    reaching gripper and tilted the closed fingers away from the floor, its grasp point then between no
    fingers."""
    robot = chain.robot
    q_start = request.q_start if request.q_start is not None else robot.q_half_sitting
    return PostureTask(
        chain.model,
        chain_q_rest(chain, np.asarray(q_start, dtype=float)),
        joint_names=[robot.gripper_joint(side) for side in ("left", "right")],
        gain=gain,
        name="grippers_held",
    )


def self_collision_task(chain: VirtualChain, margin_m: float, gain: float) -> SelfCollisionTask:
    """Self-collision (eqs. 12-13) of the robot's checked capsule pairs on the chain model, with a
    surface margin ``margin_m`` [m]. The task holds no state between evaluations, so one is built
    per chain model, margin and gain and shared by the problems on that model (cached, thread-safe)."""
    robot, model = chain.robot, chain.model
    key = (id(robot), id(model), float(margin_m), float(gain))
    with _self_collision_lock:
        hit = _self_collision.get(key)
        if hit is not None and hit[0] is robot and hit[1] is model:
            _self_collision.move_to_end(key)
            return hit[2]
    capsules = list(robot.capsules)  # services.model.Capsule is an IK capsule (CapsuleLike)
    index = {c.name: i for i, c in enumerate(robot.capsules)}
    pairs = [(index[a], index[b]) for a, b in robot.collision_pairs]
    task = SelfCollisionTask(model, capsules, pairs, margin_m=margin_m, gain=gain)
    with _self_collision_lock:
        # (robot and model are kept with the task: their ids stay unique while the entry lives)
        _self_collision[key] = (robot, model, task)
        while len(_self_collision) > SELF_COLLISION_CACHE_SIZE:
            _self_collision.popitem(last=False)
    return task


def joint_limits(chain: VirtualChain, request: FootstepPlanRequest) -> tuple[np.ndarray, np.ndarray]:
    """(q_lower, q_upper) of q~ given to the solver as hard bounds of every increment.

    Joint limits as the differential inequalities (4): the solver bounds q + alpha dq within them, i.e.
    dq <= (q_max - q) / alpha, eq. (4) with lambda = 1 / alpha. (Not also a JointLimitsTask: its rows
    would duplicate the solver's box rows, which proxsuite handles badly.) The chain's limits are the
    step bounds of every support polygon but the last (Q_i is F_i's pose in F_{i-1}); the robot's
    revolute joints keep ``joint_margin_rad`` inside their range.
    """
    model, opts = chain.model, request.options
    lower = np.array(model.lowerPositionLimit)
    upper = np.array(model.upperPositionLimit)
    # (nor the grippers: held at their start value, which may be at a limit, see grippers_held)
    grippers = {int(model.getJointId(chain.robot.gripper_joint(side))) for side in ("left", "right")}
    for jid in range(1, model.njoints):
        joint = model.joints[jid]
        # the margin applies to the robot's revolute joints (not the chain, not the grippers' slides)
        if jid in grippers:
            continue
        if joint.idx_q >= chain.chain_nq and joint.nq == 1 and joint.shortname().startswith("JointModelR"):
            lower[joint.idx_q] += opts.joint_margin_rad
            upper[joint.idx_q] -= opts.joint_margin_rad
    return lower, upper


class SaturatedTask(Task):
    """An equality task whose desired rate lambda F of eq. (2) is saturated at ``max_rate`` (norm):
    far from its goal (a hand 2 m from the ball) the task asks for a bounded motion per iteration,
    which keeps each step of the linearization small; near the goal it is eq. (2) unchanged. The
    value (eq. 5) is the inner task's."""

    def __init__(self, inner: Task, max_rate: float) -> None:
        super().__init__(inner.name, inner.gain)
        self.inner = inner
        self.base_gain = inner.gain
        self.max_rate = float(max_rate)

    def compute_error(self, q: np.ndarray, data) -> np.ndarray:
        return self.inner.compute_error(q, data)

    def compute_jacobian(self, q: np.ndarray, data) -> np.ndarray:
        return self.inner.compute_jacobian(q, data)

    def compute(self, q: np.ndarray, data) -> tuple[np.ndarray, np.ndarray]:
        F, J = self.inner.compute(q, data)
        norm = float(np.linalg.norm(F))
        # the solver reads ``gain`` right after ``compute``: b = -gain F
        self.gain = (
            self.base_gain * min(1.0, self.max_rate / (self.base_gain * norm)) if norm > 0 else self.base_gain
        )
        return F, J


def desired_task(chain: VirtualChain, task: FootstepTask, gain: float, max_rate: dict[str, float]) -> Task:
    """The IK task of one requested task on the chain model (saturated, see :class:`SaturatedTask`);
    targets are brought into the model's frame."""
    robot, model = chain.robot, chain.model
    inner: Task
    if task.kind == "reach":
        inner = FramePositionTask(
            model, robot.frames.grasp(task.hand), chain.model_point(task.target_m), gain=gain, name=task.name
        )
    elif task.kind == "orient":
        # the grasp frame's world orientation, brought into the model's frame (that of F_0)
        R_world = pin.Quaternion(np.array(task.orientation, dtype=float)).normalized().matrix()
        inner = FrameOrientationTask(
            model,
            robot.frames.grasp(task.hand),
            chain.T_root_world.rotation @ R_world,
            mask=(True, True, not task.free_yaw),  # the model's z is the world's vertical
            gain=gain,
            name=task.name,
        )
    elif task.kind == "gaze":
        inner = GazeTask(
            model,
            robot.frames.gaze,
            chain.model_point(task.target_m),
            axis_in_camera=GAZE_AXIS_IN_FRAME,
            gain=gain,
            name=task.name,
        )
    else:
        inner = PostureTask(
            model,
            chain_q_rest(chain, robot_rest(robot, task)),
            joint_names=list(robot.joint_names),
            gain=gain,
            name=task.name,
        )
    return SaturatedTask(inner, max_rate[task.kind])


def build_levels(
    chain: VirtualChain,
    request: FootstepPlanRequest,
    held: list[tuple[int, np.ndarray]],
    hold_front: bool = True,
) -> list[Level]:
    """[constraints] + one level per requested task (priority order) + the held footprints.

    ``held`` lists (footprint index i, Q_i initial value) of the footprints of an initial guess, the
    first footprints of the structure first ("the hardest to displace", section 5.1); with
    ``hold_front`` the front foot (the implicit last step Q_p) comes last, held at its folded pose
    next to the root foot.
    """
    gain = request.options.gain
    o = request.options
    rates = {"reach": o.max_rate_m, "gaze": o.max_rate_m, "posture": o.max_rate_rad, "orient": o.max_rate_rad}
    front = FrontRelativePose(chain)
    lm = {"damping": o.damping, "error_damping": o.error_damping}
    levels = [Level(tuple(constraint_tasks(chain, request, front)), name="constraints", **lm)]
    for task in request.tasks:
        levels.append(Level((desired_task(chain, task, gain, rates),), name=task.name, **lm))
    for i, Q_init in held:
        q_ref = np.zeros(chain.model.nq)
        q_ref[3 * (i - 1) : 3 * i] = Q_init
        hold = PostureTask(
            chain.model,
            q_ref,
            joint_names=chain.chain_joint_names(i),
            gain=gain,
            name=f"hold:{footprint_frame(i)}",
        )
        levels.append(Level((hold,), name=hold.name, **lm))
    if hold_front and chain.n_steps >= 1:
        folded = relative_pose(chain.start.of(chain.front_side), chain.start.of(chain.root_side))
        hold_front = FrontFootHoldTask(chain, folded, gain=gain, front=front)
        levels.append(Level((hold_front,), name=hold_front.name, **lm))
    return levels
