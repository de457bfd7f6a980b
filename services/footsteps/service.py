"""The ``footsteps`` service: footstep planning as inverse kinematics (this package) on the bus.

Run: ``python -m services.footsteps.service`` (common service options: ``--config``, ``--robot``,
``--hub``, ``--log-level``; YAML section ``footsteps:``, :class:`FootstepsConfig`).

Endpoint ``footsteps/plan`` (:mod:`services.bus.schemas.footsteps`): tasks in priority order (hand
reach point, gaze point, rest posture), disk obstacles and box obstacles (a map's boxes, as navigation
takes them: each covered by disks of its footprint), the front-foot (start-foot) choice, an initial
guess of the number of steps and the starting configuration in; the footsteps (sole poses, walking
order), the final whole-body configuration, per-task residuals, iterations, the iterations at which
steps were added and the solve time out. Stateless: apart from ``solve_time_s`` the reply is a
deterministic function of the request (the planner is bitwise reproducible). Execution (walk, then
reach) is the supervisor's job: ``walking/plan`` with the footsteps, then ``sim/execute``.
:func:`plan_reply` is the whole adapter without the bus.

Failure codes: ``invalid_request`` (unknown model, task kind or hand, a reach/gaze task without a
3-D target, a task twice, a disk with radius <= 0, a box without a positive size, ``q_start`` or
``q_rest`` of the wrong size or ``q_start`` not standing flat on the ground, ``initial_steps`` outside
0..``max_steps``, options out of range: the message names the field); ``infeasible`` (the tasks cannot
be met: the message names the worst task, its value and why Algorithm 1 stopped - local minimum, step
cap, iteration cap -, ``details`` has ``residuals``, ``tolerances``, ``reason``, ``steps``,
``iterations``, ``footsteps``); ``timeout`` (the time budget ran out first: the same message and
``details``, ``reason`` "time_budget", ``footsteps`` the best partial plan).
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense problems: threads only add overhead

import numpy as np

from services.bus.schemas import footsteps as msg
from services.bus.schemas.navigation import ObstacleMsg
from services.bus.service import Service, handles, run_service
from services.errors import InvalidRequestError
from services.footsteps.geometry import disks_covering
from services.footsteps.planner import plan_footsteps
from services.footsteps.request import (
    DiskObstacle,
    FootstepPlanRequest,
    FootstepPlanResult,
    FootstepTask,
    PlannerOptions,
    SphereObstacle,
)
from services.model import RobotModel, load_robot


@dataclass(frozen=True)
class FootstepsConfig:
    """Options of the footsteps service (YAML section ``footsteps:``).

    Attributes:
        preload: robot models loaded (and their planner warmed up) at start-up; others are loaded
            on their first request.
        warm_up: plan a short request per preloaded model at start-up, so that the first real
            request does not pay for imports and first-use allocations.
        max_time_budget_s: upper bound on a request's ``time_budget_s`` [s] (a request asking more
            is served with this budget): one request cannot hold the endpoint for minutes.
    """

    preload: tuple[str, ...] = ("hrp2_like",)
    warm_up: bool = True
    max_time_budget_s: float = 30.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_time_budget_s) and self.max_time_budget_s > 0):
            raise InvalidRequestError(f"max_time_budget_s must be > 0 s, got {self.max_time_budget_s}")


def _vector(value: np.ndarray | None, robot: RobotModel, field: str) -> tuple[float, ...] | None:
    """A (nq,) configuration as a tuple, else InvalidRequestError naming the field."""
    if value is None:
        return None
    q = np.asarray(value, dtype=float).reshape(-1)
    if q.shape != (robot.nq,) or not np.all(np.isfinite(q)):
        raise InvalidRequestError(
            f"{field} has {q.size} values but the {robot.name} model has nq={robot.nq} (finite numbers): "
            "plan from this robot's state (sim/state)",
            {"field": field, "expected": robot.nq},
        )
    return tuple(float(x) for x in q)


def _target(task: msg.Task, i: int) -> tuple[float, float, float] | None:
    if task.target is None:
        return None
    if len(task.target) != 3:
        raise InvalidRequestError(f"tasks[{i}].target must be [x, y, z] [m], got {task.target!r}")
    x, y, z = (float(v) for v in task.target)
    return (x, y, z)


# The bus's switches back to the paper's form of Algorithm 1 (``msg.Options``): False sets these
# planner options to infinity (no saturation, no per-coordinate cap, epsilon_i as written).
SWITCHES = {
    "saturation": ("max_rate_m", "max_rate_rad"),
    "dq_cap": ("dq_max",),
    "epsilon_rule": ("relative_epsilon",),
}


def planner_options(options: msg.Options | None) -> PlannerOptions:
    """The planner's options of a request's ``options`` (None fields: defaults; a switch set to false
    overrides the values it turns off)."""
    if options is None:
        return PlannerOptions()
    given = {
        f: getattr(options, f)
        for f in options.__struct_fields__
        if getattr(options, f) is not None and f not in SWITCHES
    }
    for switch, names in SWITCHES.items():
        if getattr(options, switch) is False:
            given.update({name: math.inf for name in names})
    return dataclasses.replace(PlannerOptions(), **given)


def _box_disks(boxes: list[ObstacleMsg]) -> list[tuple[float, float, float]]:
    """The disks (x, y, radius) [m] covering the footprints of ``boxes`` (kind "box": centre, full
    extents, yaw; a "cylinder": its disk); InvalidRequestError naming a malformed one."""
    out: list[tuple[float, float, float]] = []
    for i, box in enumerate(boxes):
        if len(box.center) < 2:
            raise InvalidRequestError(f"boxes[{i}].center: needs [x, y, z], got {box.center}")
        if box.kind == "cylinder":
            if not box.radius > 0.0:
                raise InvalidRequestError(f"boxes[{i}].radius: must be > 0 for a cylinder, got {box.radius}")
            out.append((float(box.center[0]), float(box.center[1]), float(box.radius)))
            continue
        if box.kind != "box" or len(box.size) < 2 or not min(box.size[:2]) > 0.0:
            raise InvalidRequestError(
                f"boxes[{i}]: expected kind 'box' with size [sx, sy, sz] > 0 (or 'cylinder'), got "
                f"kind {box.kind!r}, size {box.size}"
            )
        out.extend(disks_covering(box.footprint))
    return out


def to_planner_request(
    request: msg.PlanRequest, robot: RobotModel, max_budget_s: float
) -> FootstepPlanRequest:
    """The planner's request of a bus request (InvalidRequestError naming a malformed field)."""
    tasks = tuple(
        FootstepTask(
            kind=t.kind,
            target_m=_target(t, i),
            hand=t.hand,
            tolerance=t.tolerance,
            epsilon=t.epsilon,
            q_rest=_vector(t.q_rest, robot, f"tasks[{i}].q_rest"),
            orientation=None if t.orientation is None else tuple(float(v) for v in t.orientation),  # type: ignore[arg-type]
            free_yaw=t.free_yaw,
        )
        for i, t in enumerate(request.tasks)
    )
    return FootstepPlanRequest(
        tasks=tasks,
        robot=robot.name,
        q_start=_vector(request.q_start, robot, "q_start"),
        disks=(
            *(DiskObstacle(float(d.x), float(d.y), float(d.radius)) for d in request.disks),
            *(DiskObstacle(*disk) for disk in _box_disks(request.boxes)),
        ),
        hand_obstacles=tuple(
            SphereObstacle(*(float(v) for v in sphere.center), float(sphere.radius))
            for sphere in request.hand_obstacles
        ),
        front_foot=request.front_foot,
        initial_steps=request.initial_steps,
        max_steps=request.max_steps,
        max_iterations=request.max_iterations,
        time_budget_s=min(float(request.time_budget_s), max_budget_s),  # (nan and <= 0 are rejected)
        options=planner_options(request.options),
        record_trace=request.trace,
    )


def to_reply(result: FootstepPlanResult, robot: RobotModel) -> msg.PlanReply:
    """The bus message of a planner result."""
    values = None
    if result.trace is not None:
        values = np.array(result.trace.values, dtype=float).reshape(-1, len(result.residuals))
    return msg.PlanReply(
        model=robot.name,
        joint_names=list(robot.joint_names),
        footsteps=[msg.Footstep(side=s.side, x=s.x_m, y=s.y_m, yaw=s.yaw_rad) for s in result.footsteps],
        left_start=list(result.left_start),
        right_start=list(result.right_start),
        q_final=np.array(result.q_final, dtype=float),
        residuals=[
            msg.Residual(
                name=r.name,
                value=r.value,
                tolerance=r.tolerance if math.isfinite(r.tolerance) else None,
                solved=r.solved,
            )
            for r in result.residuals
        ],
        iterations=result.iterations,
        steps_added_at=list(result.steps_added_at),
        solve_time_s=result.solve_time_s,
        front_foot=result.front_foot,
        chain_steps=result.chain_steps,
        alternatives=[
            msg.Alternative(front_foot=f, solved=s, steps=n, posture_residual_rad=p)
            for f, s, n, p in result.alternatives
        ],
        task_values=values,
    )


def plan_reply(request: msg.PlanRequest, config: FootstepsConfig | None = None) -> msg.PlanReply:
    """Plan ``request`` (the whole endpoint, without the bus); raises the errors of the module docstring."""
    config = config or FootstepsConfig()
    robot = load_robot(request.model)
    planner_request = to_planner_request(request, robot, config.max_time_budget_s)
    return to_reply(plan_footsteps(planner_request, robot), robot)


class FootstepsService(Service):
    """Footstep planning as inverse kinematics (stateless planner)."""

    name = "footsteps"
    Config = FootstepsConfig

    def start(self) -> None:
        for model in self.config.preload:
            robot = load_robot(model)  # fail early on a bad name; warms the model cache
            if self.config.warm_up:
                plan_footsteps(
                    FootstepPlanRequest(
                        robot=robot.name,
                        tasks=(FootstepTask("reach", (0.6, -0.3, 0.8)), FootstepTask("posture")),
                        time_budget_s=5.0,
                    ),
                    robot,
                )
        self.log.info("footstep planner ready for %s", ", ".join(self.config.preload))

    @handles(msg.PLAN)
    def plan(self, request: msg.PlanRequest) -> msg.PlanReply:
        reply = plan_reply(request, self.config)
        self.log.info(
            "%s: %d steps (%s foot last), %d iterations, planned in %.3f s",
            reply.model,
            len(reply.footsteps),
            reply.front_foot,
            reply.iterations,
            reply.solve_time_s,
        )
        return reply


if __name__ == "__main__":
    raise SystemExit(run_service(FootstepsService))
