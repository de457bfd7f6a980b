"""Configuration of the perception service (YAML section ``perception:`` overrides the defaults)."""

from __future__ import annotations

from dataclasses import dataclass

from services.bus.limits import check_budget
from services.errors import InvalidRequestError
from vision.stereo import METHODS


@dataclass(frozen=True)
class PerceptionConfig:
    """Options of the perception service.

    Attributes:
        models_dir: directory of the object models ``<name>.json`` ("" = vision/models, the learned ones).
        robot_model: robot model assumed for requests that give ``q`` but no ``model``.
        stereo_method: default stereo estimator: "centroid" (most accurate, see vision/README.md), "bm",
            "sgbm" or "edges".
        max_depth_m: farthest object searched [m] (bounds the disparities accepted).
        render_timeout_s: how long to wait for ``sim/render`` (and ``sim/state``) [s] (within the
            request's budget; at most ``MAX_BUDGET_S``): also the render's own time budget, so that the
            sim stops when perception stops waiting.
        time_budget_s: wall-clock budget of a ``perception/locate`` request that gives none [s] (at most
            ``services.bus.limits.MAX_BUDGET_S``); past it the reply is ``timeout``.
        check_render_pose_m: warn in the log when the pose the sim rendered from is farther than this
            from the pose computed from the request's ``q`` (a stale ``q``) [m]; the pose used is always
            the one from ``q``.
    """

    models_dir: str = ""
    robot_model: str = "hrp2_like"
    stereo_method: str = "centroid"
    max_depth_m: float = 8.0
    render_timeout_s: float = 10.0
    check_render_pose_m: float = 0.01
    time_budget_s: float = 30.0

    def __post_init__(self) -> None:
        check_budget(self.time_budget_s, "perception.time_budget_s")
        check_budget(self.render_timeout_s, "perception.render_timeout_s")
        if self.stereo_method not in METHODS:
            raise InvalidRequestError(
                f"perception.stereo_method must be one of {list(METHODS)}, got {self.stereo_method!r}"
            )
        if not self.max_depth_m > 0.5:
            raise InvalidRequestError("perception.max_depth_m must be > 0.5 m")
