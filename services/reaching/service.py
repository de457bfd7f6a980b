"""The ``reaching`` service: whole-body reaching with support polygon reshaping on the bus.

Run: ``python -m services.reaching.service [--model talos]`` (plus the common service options:
``--config``, ``--robot``, ``--hub``, ``--log-level``); options can be given in the ``reaching:`` section
of the config file (:class:`ReachingConfig`: the robot model and every :class:`ReachingOptions` field).

Endpoint ``reaching/reach`` (:mod:`services.bus.schemas.reaching`): a stateless planner, the reply is a
deterministic function of the request. Failure codes: ``invalid_request`` (unknown hand, malformed
target or orientation, ``q_start`` of the wrong size or not standing on flat ground), ``infeasible``
(the message and ``details.criterion`` name the criterion that failed and why reshaping did not help;
``details.reason`` ``hand_obstacle``: the arm passes within ``hand_clearance_m`` of a ``hand_obstacles``
sphere however it is planned, ``details.sphere`` and ``details.link`` name them),
``timeout`` (``time_budget_s`` ran out: ``details.stage`` and the ``attempts`` made).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense problems: threads only add overhead

import numpy as np

from services import budget
from services.bus.limits import MAX_BUDGET_S, check_budget
from services.bus.schemas import reaching as msg
from services.bus.service import Service, handles, run_service
from services.errors import InvalidRequestError
from services.ik.hand_obstacles import SphereObstacle
from services.model import load_robot
from services.model.options import add_model_argument, with_model
from services.reaching.monitors import MonitorSeries
from services.reaching.options import ReachingOptions
from services.reaching.planner import ReachPlanner
from services.reaching.request import ReachRequest, ReachTiming, quaternion_to_matrix
from services.reaching.result import ReachResult


@dataclass(frozen=True)
class ReachingConfig(ReachingOptions):
    """Options of the service: the robot model (``hrp2_like`` or ``talos``), whether to build the default
    planner and its reach envelopes at start-up (each envelope height is measured at the first request
    that needs it: ``services.reaching.envelope``), the wall-clock budget of a
    request that gives none (``time_budget_s`` [s], at most ``services.bus.limits.MAX_BUDGET_S``; past
    it the reply is ``timeout``) and the planner options."""

    model: str = "hrp2_like"
    warm_up: bool = True
    time_budget_s: float = MAX_BUDGET_S

    def __post_init__(self) -> None:
        super().__post_init__()
        check_budget(self.time_budget_s, "reaching.time_budget_s")

    def planner_options(self, **overrides: Any) -> ReachingOptions:
        """The :class:`ReachingOptions` part, with ``overrides`` (None values ignored)."""
        names = {f.name for f in dataclasses.fields(ReachingOptions)}
        values = {k: getattr(self, k) for k in names}
        values.update({k: v for k, v in overrides.items() if v is not None})
        return ReachingOptions(**values)


class ReachingService(Service):
    """Whole-body reaching with task-driven support polygon reshaping (stateless planner)."""

    name = "reaching"
    Config = ReachingConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_model_argument(parser)

    @classmethod
    def configure(cls, config: ReachingConfig, args: argparse.Namespace) -> ReachingConfig:
        return with_model(config, args.model)

    def start(self) -> None:
        self.robot = load_robot(self.config.model)
        self._planners: dict[ReachingOptions, ReachPlanner] = {}
        default = self._planner(self.config.planner_options())
        if self.config.warm_up:
            for hand in ("left", "right"):
                default.envelope(hand)
        self.log.info("reaching planner ready for %s", self.robot.name)

    def _planner(self, options: ReachingOptions) -> ReachPlanner:
        planner = self._planners.get(options)
        if planner is None:
            if len(self._planners) >= 4:
                self._planners.pop(next(iter(self._planners)))
            planner = self._planners[options] = ReachPlanner(self.robot, options)
        return planner

    @handles(msg.REACH)
    def reach(self, request: msg.ReachRequest) -> msg.ReachReply:
        q_start = np.asarray(request.q_start, dtype=float).reshape(-1)
        if q_start.shape != (self.robot.nq,):
            raise InvalidRequestError(
                f"q_start has {q_start.size} values but the {self.robot.name} model of this service has "
                f"nq={self.robot.nq}: plan from this robot's state (sim/state)",
                {"field": "q_start", "expected": self.robot.nq},
            )
        rotation = None if request.orientation is None else quaternion_to_matrix(request.orientation)
        options = self.config.planner_options(
            weighted=request.weighted,
            joint_limit_selection_rad=request.joint_limit_selection_rad,
            ee_error_threshold_m=request.ee_error_threshold_m,
        )
        with budget.within(request.time_budget_s or self.config.time_budget_s):
            result = self._planner(options).plan(
                ReachRequest(
                    hand=request.hand,
                    target_world_m=np.asarray(request.target, dtype=float),
                    q_start=q_start,
                    R_world_hand=rotation,
                    gaze=request.gaze,
                    allow_stepping=request.allow_stepping,
                    q_posture=None if request.posture is None else np.asarray(request.posture, dtype=float),
                    timing=_timing(request),
                    hand_obstacles=tuple(
                        SphereObstacle(*(float(v) for v in sphere.center), float(sphere.radius))
                        for sphere in request.hand_obstacles
                    ),
                    hand_clearance_m=request.hand_clearance_m,
                )
            )
        return to_reply(result, list(self.robot.joint_names))


def _timing(request: msg.ReachRequest) -> ReachTiming | None:
    """The request's own timing, or None when it gives none (the service's defaults)."""
    values = (request.hand_speed_m_s, request.min_duration_s, request.final_hold_s)
    return None if all(v is None for v in values) else ReachTiming(*values)


def _monitors(series: MonitorSeries) -> msg.Monitors:
    return msg.Monitors(
        times_s=series.times_s,
        manipulability=series.manipulability,
        ee_error_m=series.ee_error_m,
        joint_limit_margin_rad=series.joint_limit_margin_rad,
        joint_speed_ratio=series.joint_speed_ratio,
        torque_ratio=series.torque_ratio,
    )


def to_reply(result: ReachResult, joint_names: list[str]) -> msg.ReachReply:
    """The bus message of a planner result."""
    attempts = []
    for a in result.attempts:
        v = a.violation
        attempts.append(
            msg.Attempt(
                kind=a.kind,
                steps=a.n_steps,
                violation="" if v is None else v.criterion,
                time_s=0.0 if v is None else v.time_s,
                value=0.0 if v is None else float(v.value),
                threshold=0.0 if v is None else float(v.threshold),
                wall_time_s=a.wall_time_s,
            )
        )
    return msg.ReachReply(
        model=result.robot,
        joint_names=joint_names,
        dt_s=result.dt_s,
        q=np.ascontiguousarray(result.q),
        duration_s=result.duration_s,
        stepped=result.stepped,
        footsteps=[
            msg.Footstep(side=s.side, x=float(s.pose.x_m), y=float(s.pose.y_m), yaw=float(s.pose.yaw_rad))
            for s in result.footsteps
        ],
        monitors=_monitors(result.monitors),
        no_step_monitors=_monitors(result.no_step_monitors),
        attempts=attempts,
        manipulability_threshold=result.thresholds.manipulability,
        ee_error_threshold_m=result.thresholds.ee_error_m,
        zmp_multibody=np.ascontiguousarray(result.zmp_multibody_m),
        zmp_planned=np.ascontiguousarray(result.zmp_planned_m),
        zmp_distance_m=np.ascontiguousarray(result.zmp_distance_m),
        phase=np.ascontiguousarray(result.phase, dtype=np.int8),
        left_sole=np.ascontiguousarray(result.left_sole),
        right_sole=np.ascontiguousarray(result.right_sole),
        hand_error_m=result.hand_error_m,
        max_sole_slide_m=result.max_sole_slide_m,
        planning_time_s=result.wall_time_s,
    )


if __name__ == "__main__":
    raise SystemExit(run_service(ReachingService))
