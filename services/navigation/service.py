"""The ``navigation`` service: the two-stage planner (services/navigation) on the bus.

Run: ``python -m services.navigation.service [--model hrp2_like]`` (plus the common service options:
``--config``, ``--robot``, ``--hub``, ``--log-level``; the ``navigation:`` section of the config file
holds :class:`NavigationConfig`).

Endpoint ``navigation/goto`` (:mod:`services.bus.schemas.navigation`): obstacles, the robot's starting
configuration, a goal pose or object and an optional carried bar in; the path, footsteps, 5 ms whole-body
trajectory and reshaping report out: the trajectory stage 2 checked for collisions and reshaped, to be
executed as it is. A near goal whose car-like path is a detour is walked straight (``path_curve``
"straight", services/navigation/straight.py). Stateless: the reply is a function of the request.
``total_budget_s`` bounds the whole goto (each stage-1 search gets at most what is left of it); past it
the reply is ``timeout`` with ``details.stage``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np

from services import budget
from services.bus.limits import MAX_BUDGET_S, check_budget
from services.bus.schemas import navigation as msg
from services.bus.service import Service, handles, run_service
from services.collision.carried import CarriedBar
from services.collision.obstacles import Scene, obstacle_from_msg
from services.errors import InvalidRequestError
from services.model import load_robot
from services.model.options import add_model_argument, with_model
from services.navigation.geometry import Pose2D
from services.navigation.goals import ObjectGoal
from services.navigation.goto import GotoOptions, GotoResult, plan_goto, start_pose
from services.navigation.path import PlannerConfig
from services.navigation.reshaping import ReshapeOptions, SamplingOptions
from services.navigation.stage2 import Stage2Options
from services.navigation.straight import StraightWalkOptions
from services.walking.timing import WalkTiming

DEFAULT_BOUNDS_MARGIN_M = 1.5
#: Largest side of the floor a request may plan over [m] (given ``bounds`` or the box around start,
#: goal and obstacles): the path search, the footsteps and the whole-body trajectory grow with it.
MAX_FLOOR_SIDE_M = 30.0


@dataclass(frozen=True)
class NavigationConfig:
    """Options of the navigation service.

    Attributes:
        model: robot model the plans are for (``services.model.load_robot``): ``hrp2_like`` or ``talos``.
        max_time_budget_s: largest stage-1 search budget a request may ask for [s].
        max_iterations: largest reshaping iteration budget a request may ask for.
        goto_budget_s: wall-clock budget of a whole goto whose request gives no ``total_budget_s`` [s]
            (at most ``services.bus.limits.MAX_BUDGET_S``); past it the reply is ``timeout``.
    """

    model: str = "hrp2_like"
    max_time_budget_s: float = 10.0
    max_iterations: int = 10
    goto_budget_s: float = MAX_BUDGET_S

    def __post_init__(self) -> None:
        check_budget(self.goto_budget_s, "navigation.goto_budget_s")
        if not (math.isfinite(self.max_time_budget_s) and self.max_time_budget_s > 0):
            raise InvalidRequestError(
                f"navigation max_time_budget_s must be > 0 s, got {self.max_time_budget_s}"
            )
        if self.max_iterations < 1:
            raise InvalidRequestError(f"navigation max_iterations must be >= 1, got {self.max_iterations}")


def scene_from_request(request: msg.GotoRequest, start: Pose2D) -> Scene:
    """The planner's scene: the obstacles and the floor bounds (given, or around start, goal and
    obstacles with a 1.5 m margin)."""
    obstacles = tuple(obstacle_from_msg(o, i) for i, o in enumerate(request.obstacles))
    if request.bounds:
        if len(request.bounds) != 4:
            raise InvalidRequestError(
                f"bounds must be [xmin, xmax, ymin, ymax], got {request.bounds}", {"field": "bounds"}
            )
        bounds = tuple(float(v) for v in request.bounds)
    else:
        xs, ys = [start.x_m], [start.y_m]
        if request.goal_pose:
            xs.append(float(request.goal_pose[0]))
            ys.append(float(request.goal_pose[1]))
        for o in obstacles:
            r = o.bounding_radius_xy_m
            xs += [o.center_xyz_m[0] - r, o.center_xyz_m[0] + r]
            ys += [o.center_xyz_m[1] - r, o.center_xyz_m[1] + r]
        m = DEFAULT_BOUNDS_MARGIN_M
        bounds = (min(xs) - m, max(xs) + m, min(ys) - m, max(ys) + m)
    return Scene(obstacles, bounds)  # type: ignore[arg-type]


def check_floor(scene: Scene) -> None:
    """InvalidRequestError before any work for a floor larger than MAX_FLOOR_SIDE_M."""
    xmin, xmax, ymin, ymax = scene.bounds_xy_m  # increasing: checked by Scene
    side = max(xmax - xmin, ymax - ymin)
    if side > MAX_FLOOR_SIDE_M:
        raise InvalidRequestError(
            f"the floor to plan over spans {side:.1f} m (bounds, or start, goal and obstacles with a "
            f"{DEFAULT_BOUNDS_MARGIN_M} m margin): at most {MAX_FLOOR_SIDE_M:.0f} m per navigation/goto; "
            "walk there in several requests",
            {"field": "bounds", "limit_m": MAX_FLOOR_SIDE_M},
        )


def goal_from_request(request: msg.GotoRequest) -> Pose2D | ObjectGoal:
    """The goal: a pose or an object; InvalidRequestError unless exactly one is given."""
    if bool(request.goal_pose) == bool(request.goal_object):
        raise InvalidRequestError(
            "give exactly one goal: goal_pose [x, y, theta] or goal_object (an obstacle's name)",
            {"field": "goal_pose"},
        )
    if request.goal_object:
        return ObjectGoal(request.goal_object, request.goal_distance_m, request.goal_side or None)
    if len(request.goal_pose) != 3:
        raise InvalidRequestError(
            f"goal_pose must be [x, y, theta], got {request.goal_pose}", {"field": "goal_pose"}
        )
    return Pose2D(*(float(v) for v in request.goal_pose))


def _finite_or_none(value: float) -> float | None:
    """JSON has no infinity (msgspec writes null): an unbounded value travels as None."""
    return value if math.isfinite(value) else None


def _empty() -> np.ndarray:
    return np.zeros(0)


def reply_from_result(model: str, result: GotoResult) -> msg.GotoReply:
    """The ``goto`` reply of a plan."""
    path, motion, seq = result.path, result.motion, result.footsteps.sequence
    wb = motion.wholebody
    carried = motion.bar_centre_m is not None
    report = motion.report()
    goal = result.goal
    return msg.GotoReply(
        model=model,
        goal=[goal.x_m, goal.y_m, goal.theta_rad],
        path_xy_m=path.xy_m,
        path_theta_rad=path.theta_rad,
        path_s_m=path.s_m,
        path_forward=path.forward.astype(np.uint8),
        path_curve=path.curve,
        left_start=[seq.left_start.x_m, seq.left_start.y_m, seq.left_start.yaw_rad],
        right_start=[seq.right_start.x_m, seq.right_start.y_m, seq.right_start.yaw_rad],
        step_sides=[s.side for s in seq.steps],
        step_poses=np.array([[s.pose.x_m, s.pose.y_m, s.pose.yaw_rad] for s in seq.steps]).reshape(-1, 3),
        dt_s=float(motion.pattern.dt_s),
        q=motion.q,
        com_m=wb.com_m,
        zmp_m=wb.zmp_multibody_m,
        duration_s=float(motion.times_s[-1]),
        reshaping=msg.ReshapingReport(
            iterations=report["iterations"],
            segments=[msg.LiftSegment(**s) for s in report["segments_lifted"]],
            min_clearance_m=_finite_or_none(float(report["min_clearance_m"])),
            zmp_margin_m=float(report["zmp_margin_m"]),
            hand_error_m=float(report["hand_error_m"]),
            collisions_per_iteration=[len(it.events) for it in motion.iterations],
            bar_height_nominal_m=motion.bar_height_nominal_m if carried else _empty(),
            bar_height_before_m=motion.bar_height_first_m if carried else _empty(),
            bar_height_planned_m=motion.bar_height_planned_m if carried else _empty(),
            bar_height_m=motion.bar_centre_m[:, 2].copy() if carried else _empty(),
        ),
        timings_s=dict(result.timings_s),
        replans=result.replans,
    )


def goto_options(request: msg.GotoRequest) -> GotoOptions:
    """The planner's options of a ``navigation/goto`` request: the path search (turning radius, budget,
    seed), the walk's double support, the carry height and the smooth reshaping (iterations, mode
    ``sample``/``lift`` and the sampler's seed)."""
    return GotoOptions(
        planner=PlannerConfig(
            turning_radius_m=request.turning_radius_m,
            time_budget_s=request.time_budget_s,
            seed=request.seed,
        ),
        stage2=Stage2Options(
            timing=WalkTiming(double_support_s=request.double_support_s),
            carry_height_m=request.carry_height_m,
            reshape=ReshapeOptions(
                max_iterations=request.max_iterations,
                mode=request.reshape_mode,
                sampling=SamplingOptions(seed=request.reshape_seed),
            ),
        ),
        straight=StraightWalkOptions() if request.straight_walks else None,
    )


class NavigationService(Service):
    """Walking plans: car-like paths, footsteps, whole-body motion with smooth reshaping of a carried bar."""

    name = "navigation"
    Config = NavigationConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_model_argument(parser)

    @classmethod
    def configure(cls, config: NavigationConfig, args: argparse.Namespace) -> NavigationConfig:
        return with_model(config, args.model)

    def start(self) -> None:
        self.robot = load_robot(self.config.model)

    @handles(msg.GOTO)
    def goto(self, request: msg.GotoRequest) -> msg.GotoReply:
        cfg: NavigationConfig = self.config
        if not 0.0 < request.time_budget_s <= cfg.max_time_budget_s:
            raise InvalidRequestError(
                f"time_budget_s must be within 0 and {cfg.max_time_budget_s} s, got {request.time_budget_s}",
                {"field": "time_budget_s"},
            )
        if not 1 <= request.max_iterations <= cfg.max_iterations:
            raise InvalidRequestError(
                f"max_iterations must be within 1 and {cfg.max_iterations}, got {request.max_iterations}",
                {"field": "max_iterations"},
            )
        robot = self.robot
        q_start = robot.check_q(np.asarray(request.q_start, dtype=float), "q_start")
        goal = goal_from_request(request)
        scene = scene_from_request(request, start_pose(robot, q_start))
        check_floor(scene)
        bar = None
        if request.carried is not None:
            c = request.carried
            bar = CarriedBar(length_m=c.length_m, radius_m=c.radius_m, mass_kg=c.mass_kg)
        options = goto_options(request)
        with budget.within(request.total_budget_s or cfg.goto_budget_s):
            result = plan_goto(robot, scene, q_start, goal, bar, options)
        return reply_from_result(robot.name, result)


def main(argv: list[str] | None = None) -> int:
    """``python -m services.navigation.service``."""
    return run_service(NavigationService, argv)


if __name__ == "__main__":
    raise SystemExit(main())
