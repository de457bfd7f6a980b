"""Did the fetch really work? Checks on the sim's ground truth and on the recorded log, for tests and
benchmarks ONLY.

The supervisor never calls this (it knows the world through perception); tests and
``scripts/bench fetch`` use it to judge a run independently of what the supervisor believes, and to
count what really went over the bus (the recorder's MCAP log, not the supervisor's own counters).
"""

from __future__ import annotations

import math
from pathlib import Path

from services.bus.mcaplog import LogReader
from services.bus.schemas import sim as sim_msg
from services.bus.spec import EndpointSpec

#: What the stack's recorder needs to write for :func:`requests_in_log` of ``footsteps/plan``: the
#: footstep planner's messages only (a fetch's full log is ~40 MB and recording it costs CPU).
FOOTSTEPS_RECORD_KEYS = "hrp/*/footsteps/**"


def record_config(path: str | Path, key_expr: str = FOOTSTEPS_RECORD_KEYS, chunk_bytes: int = 1 << 20) -> str:
    """Write a YAML file with the recorder's section (``record:``: ``key_expr``, no Foxglove views,
    chunks of ``chunk_bytes``) for ``running_stack(config_path=...)``; its path."""
    Path(path).write_text(
        f'record:\n  key_expr: "{key_expr}"\n  foxglove_views: false\n  chunk_size_bytes: {chunk_bytes}\n'
    )
    return str(path)


def requests_in_log(path: str | Path, endpoint: EndpointSpec, windows: list[tuple[int, int]]) -> list[int]:
    """Requests to ``endpoint`` in the MCAP log ``path`` whose log time [ns since the epoch, the
    recorder's clock] falls in each ``(start, end)`` window (e.g. one per fetch)."""
    suffix = f"/{endpoint.path}/request"
    counts = [0] * len(windows)
    for message in LogReader(path).messages():
        if not message.key.endswith(suffix):
            continue
        for k, (start, end) in enumerate(windows):
            if start <= message.log_time_ns <= end:
                counts[k] += 1
    return counts


def ball_on_table(
    gt: sim_msg.GroundTruthReply, ball: str = "orange_ball", table: str = "yellow_table"
) -> tuple[bool, str]:
    """(True, "") when ``ball`` rests on ``table``'s top: not held, its centre above the top rectangle
    and 0 to 6 cm above the top plus its radius; else (False, why)."""
    objects = {o.name: o for o in gt.objects}
    b, t = objects.get(ball), objects.get(table)
    if b is None or t is None:
        return False, f"{ball} or {table} is not in the scene"
    if b.held_by:
        return False, f"{ball} is still held by the {b.held_by} hand"
    qx, qy, qz, qw = t.quaternion
    yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    dx, dy = b.position[0] - t.position[0], b.position[1] - t.position[1]
    local_x = math.cos(yaw) * dx + math.sin(yaw) * dy
    local_y = -math.sin(yaw) * dx + math.cos(yaw) * dy
    sx, sy, top = t.size_m[:3]
    above = b.position[2] - (top + b.radius_m)
    if abs(local_x) <= sx / 2 and abs(local_y) <= sy / 2 and -0.01 <= above <= 0.06:
        return True, ""
    x, y, z = b.position
    return False, f"{ball} is at ({x:.2f}, {y:.2f}, {z:.2f}) m, not on {table}"
