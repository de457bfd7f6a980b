"""Did the fetch really work? A check on the sim's ground truth, for tests and benchmarks ONLY.

The supervisor never calls this (it knows the world through perception); tests and
``scripts/bench fetch`` use it to judge a run independently of what the supervisor believes.
"""

from __future__ import annotations

import math

from services.bus.schemas import sim as sim_msg


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
