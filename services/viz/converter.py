"""Which bus message becomes which Foxglove messages: one stateful router over :mod:`services.viz.convert`.

:class:`Converter` keeps what the pure converters need between messages: the robot model (named, or
recognised from the first joint state's size), the time of the last transforms (decimation to
``transform_hz``) and the last reaching request (its target). ``convert(key, frame, log_time_ns)``
never raises: a message it cannot read gives nothing (counted in ``errors``).
"""

from __future__ import annotations

import functools
import json
from typing import Any

import numpy as np

from services.bus import keys
from services.bus.codec import decode
from services.bus.mcaplog import View
from services.bus.schemas import footsteps as fs_msg
from services.bus.schemas import navigation as nav_msg
from services.bus.schemas import perception as per_msg
from services.bus.schemas import reaching as reach_msg
from services.bus.schemas import sim as sim_msg
from services.bus.schemas import walking as walk_msg
from services.bus.schemas.common import ErrorInfo, LauncherEvent, LogLine
from services.bus.schemas.supervisor import SupervisorEvent
from services.viz import common as c
from services.viz import convert
from services.viz.convert import DEFAULT_SOLE_M, JsonMessage, Out

#: Decoded message type of each converted ``service/name[/mirror]`` key tail.
_TYPES: dict[str, type] = {
    "sim/joint_state": sim_msg.JointState,
    "sim/ground_truth/reply": sim_msg.GroundTruthReply,
    "sim/render/reply": sim_msg.RenderReply,
    "sim/snapshot/reply": sim_msg.SnapshotReply,
    "navigation/goto/request": nav_msg.GotoRequest,
    "navigation/goto/reply": nav_msg.GotoReply,
    "walking/plan/reply": walk_msg.PlanReply,
    "footsteps/plan/reply": fs_msg.PlanReply,
    "reaching/reach/request": reach_msg.ReachRequest,
    "reaching/reach/reply": reach_msg.ReachReply,
    "perception/locate/reply": per_msg.LocateReply,
    "supervisor/events": SupervisorEvent,
    "launcher/events": LauncherEvent,
}
#: The robot body is re-sent this often [s] (a viewer that joins late, a log opened in the middle).
BODY_PERIOD_S = 5.0
HAND_PATH_POINTS = 100


def route(key: str) -> str:
    """``service/name[/mirror]`` of a bus key; ``error`` for error mirrors, ``log`` for a service's log
    lines; "" if not converted."""
    try:
        _robot, service, rest = keys.parse(key)
    except ValueError:
        return ""
    tail = f"{service}/{rest}"
    if tail in _TYPES:
        return tail
    if rest.endswith("/error"):
        return "error"
    if rest == "log":
        return "log"
    return ""


def key_exprs(robot: str) -> list[str]:
    """The keys the converters read, as zenoh key expressions (what :func:`route` accepts). The live
    view subscribes to these only: ``hrp/**`` would also bring every 200 Hz state topic into Python
    and turn on every endpoint's request/reply mirrors (the sim's execute requests: 9 MB a fetch)
    that nothing here shows."""
    base = f"{keys.PREFIX}/{robot}"
    return [*(f"{base}/{tail}" for tail in _TYPES), f"{base}/*/*/error", f"{base}/*/log"]


class Converter:
    """Bus messages -> Foxglove messages (see the module docstring)."""

    def __init__(self, model: str = "", transform_hz: float = 30.0) -> None:
        self.model_name = model
        self.period_ns = int(1e9 / transform_hz) if transform_hz > 0 else 0
        self.robot_view: Any = None
        self._last_tf_ns = -(1 << 62)
        self._last_body_ns = -(1 << 62)
        self._reach_request: reach_msg.ReachRequest | None = None
        self.errors = 0
        if model:
            self._load(model)

    # Public -----------------------------------------------------------------------------------------
    def wants(self, key: str, log_time_ns: int) -> bool:
        """Whether ``convert`` would make something of this message (cheap: no decoding)."""
        tail = route(key)
        if tail == "sim/joint_state":
            return log_time_ns - self._last_tf_ns >= self.period_ns
        return bool(tail)

    def convert(self, key: str, frame: bytes, log_time_ns: int) -> Out:
        """The Foxglove messages made from one bus message (possibly none)."""
        tail = route(key)
        if not tail:
            return []
        try:
            if tail == "error":
                _robot, service, rest = keys.parse(key)
                return convert.error_log(
                    log_time_ns, service, rest.rsplit("/", 1)[0], decode(frame, ErrorInfo)
                )
            if tail == "log":
                return convert.service_log(log_time_ns, decode(frame, LogLine))
            if tail == "sim/joint_state" and log_time_ns - self._last_tf_ns < self.period_ns:
                return []
            return self._convert(tail, decode(frame, _TYPES[tail]), log_time_ns)
        except Exception:  # a message this version cannot read: nothing to show, the stack goes on
            self.errors += 1
            return []

    def views(self, key: str, frame: bytes, log_time_ns: int) -> list[View]:
        """The same, encoded for an MCAP log (:class:`services.bus.mcaplog.View`)."""
        return [encoded(topic, msg, log_time_ns) for topic, msg in self.convert(key, frame, log_time_ns)]

    # Internals --------------------------------------------------------------------------------------
    def _load(self, name: str) -> None:
        from services.model import load_robot
        from services.viz.robot import RobotView

        self.robot_view = RobotView(load_robot(name))
        self.model_name = name

    def _recognise(self, nq: int) -> None:
        from services.model import load_robot, robot_names

        for name in robot_names():
            if load_robot(name).nq == nq:
                self._load(name)
                return
        raise ValueError(f"no robot model has nq = {nq}")

    @property
    def sole_m(self) -> tuple[float, float]:
        return self.robot_view.robot.sole_size_m if self.robot_view is not None else DEFAULT_SOLE_M

    def _convert(self, tail: str, msg: Any, t: int) -> Out:
        if tail == "sim/joint_state":
            q = np.asarray(msg.q, dtype=float)
            if self.robot_view is None or self.robot_view.robot.nq != len(q):
                self._recognise(len(q))
            self._last_tf_ns = t
            out: Out = [(c.TF, self.robot_view.transforms(q, t))]
            if t - self._last_body_ns >= BODY_PERIOD_S * 1e9:
                self._last_body_ns = t
                out.append((c.ROBOT, self.robot_view.body(t)))
            return out
        if tail == "sim/ground_truth/reply":
            return convert.world_objects(t, msg)
        if tail == "sim/render/reply":
            out = []
            for image in msg.images:
                cams = self.robot_view.robot.cameras if self.robot_view is not None else {}
                frame_id = cams[image.name].frame if image.name in cams else image.name
                out += convert.camera(t, image, frame_id)
            return out
        if tail == "sim/snapshot/reply":
            return convert.snapshot(t, msg)
        if tail == "navigation/goto/request":
            return convert.map_obstacles(t, msg)
        if tail == "navigation/goto/reply":
            return convert.navigation_plan(t, msg, self.sole_m)
        if tail == "walking/plan/reply":
            return convert.walking_plan(t, msg, self.sole_m)
        if tail == "footsteps/plan/reply":
            return convert.footstep_planner_result(t, msg, self.sole_m)
        if tail == "reaching/reach/request":
            self._reach_request = msg
            return convert.reach_target(t, msg)
        if tail == "reaching/reach/reply":
            return convert.reach_plan(t, msg, self._hand_path(msg), self.sole_m)
        if tail == "perception/locate/reply":
            return convert.sighting(t, msg)
        if tail == "supervisor/events":
            return convert.supervisor_log(t, msg)
        if tail == "launcher/events":
            return convert.launcher_log(t, msg)
        return []

    def _hand_path(self, reply: reach_msg.ReachReply) -> np.ndarray:
        """The grasp frame's positions along the reply's trajectory (forward kinematics) [m]."""
        q = np.asarray(reply.q, dtype=float)
        if self.robot_view is None or self.robot_view.robot.nq != q.shape[-1]:
            self._recognise(q.shape[-1])
        robot = self.robot_view.robot
        side = self._reach_request.hand if self._reach_request is not None else "right"
        frame = robot.frames.grasp(side)
        idx = np.unique(np.linspace(0, len(q) - 1, min(len(q), HAND_PATH_POINTS)).round().astype(int))
        return np.array([robot.frame_pose(q[i], frame).translation for i in idx])


def encoded(topic: str, msg: Any, log_time_ns: int) -> View:
    """One converter output as an MCAP view (protobuf for foxglove messages, JSON for JsonMessage)."""
    if isinstance(msg, JsonMessage):
        return View(topic, msg.schema_name, "jsonschema", _json_schema_bytes(msg.schema_name, msg.schema),
                    "json", msg.encode(), log_time_ns)  # fmt: skip
    name, encoding, data = _schema_of(type(msg))
    return View(topic, name, encoding, data, "protobuf", msg.encode(), log_time_ns)


@functools.cache
def _schema_of(type_: type) -> tuple[str, str, bytes]:
    schema = type_.get_schema()
    return schema.name, schema.encoding, bytes(schema.data)


_json_schemas: dict[str, bytes] = {}


def _json_schema_bytes(name: str, schema: dict[str, Any]) -> bytes:
    data = _json_schemas.get(name)
    if data is None:
        data = _json_schemas[name] = json.dumps(schema).encode()
    return data
