"""The legs' swept volume of a planned walk against the map's boxes, in 3D (``walking/goal``).

:func:`services.walking.goals.check_clear` checks the footprints on the floor; a leg sweeps more than
its sole: a foot lifting from the ground brings its knee and thigh forward, and the first weight
transfer moves the hips over the support foot. A walk that starts beside a box (after a reach into
it) can bring a leg into the box without any footprint entering it (fetch seed 37: stepping back
from the box, the right thigh, 3 cm from it, touched it as its foot lifted). The whole-body motion
the walking planner made is checked here with the 3D checker navigation's stage 2 uses (the robot's
collision shapes against the boxes, :class:`services.collision.motion.MotionChecker`, in the shared
package below both): one concept, one place.
Pure: no bus here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from services.bus.schemas.walking import REASON_BLOCKED
from services.collision.motion import MotionChecker
from services.collision.obstacles import Obstacle, Scene
from services.errors import InfeasibleError

LEGS = "legs"
"""The part group of :mod:`services.collision.motion` checked here."""


def check_legs_clear(
    robot: Any,
    qs: np.ndarray,
    dt_s: float,
    obstacles: Sequence[Obstacle],
    *,
    clearance_m: float,
    tolerance_m: float = 0.005,
    stride: int = 4,
) -> None:
    """Check that no leg of the motion ``qs`` (n, nq) [every ``dt_s`` s] of ``robot`` (a
    ``services.model`` robot) comes nearer to a box of ``obstacles`` (world frame) than
    ``clearance_m`` [m], or, for a box a leg starts nearer to (a walk away from a box it stands
    beside), nearer than it starts (less ``tolerance_m`` [m]): a walk may leave a box, not sweep a leg
    into it. Every ``stride``-th sample is checked (4: every 20 ms at 5 ms).

    Raises:
        InfeasibleError: ``details``: ``reason`` ``REASON_BLOCKED``, ``obstacle``, ``link`` (the
            closest collision shape), ``distance_m``, ``required_m``, ``time_s``.
    """
    if not obstacles:
        return
    xs = [float(v) for v in qs[:, 0]]
    ys = [float(v) for v in qs[:, 1]]
    bounds = (min(xs) - 5.0, max(xs) + 5.0, min(ys) - 5.0, max(ys) + 5.0)
    check = MotionChecker(robot, Scene(tuple(obstacles), bounds)).check(qs, dt_s, stride=stride)
    g = check.groups.index(LEGS)
    for j, name in enumerate(check.obstacles):
        d = check.distance_m[:, g, j]
        if not np.isfinite(d).any():
            continue
        start = float(d[0]) if np.isfinite(d[0]) else clearance_m
        need = min(clearance_m, start) - tolerance_m
        k = int(np.argmin(d))
        if float(d[k]) < need:
            link = check.shape_names[int(check.closest_shape[k, g, j])]
            raise InfeasibleError(
                f"the walk brings a leg ({link}) {100 * float(d[k]):.1f} cm from {name} at "
                f"t={float(check.times_s[k]):.2f} s (it starts {100 * start:.1f} cm from it; a leg keeps "
                f"{100 * need:.1f} cm): walk away from it another way",
                {
                    "reason": REASON_BLOCKED,
                    "obstacle": name,
                    "link": link,
                    "distance_m": float(d[k]),
                    "required_m": need,
                    "time_s": float(check.times_s[k]),
                },
            )
