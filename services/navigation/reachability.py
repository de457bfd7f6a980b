"""A cheap proof that a goal is enclosed, before spending a sampling planner's budget on it.

Any collision-free footprint contains its inscribed disc, so along every feasible path the base stays at
distance >= r_in (the footprint's inradius) from all floor projections (and at the arms' inradius from
the obstacles at arm height). The checker's distance grid,
thresholded conservatively (grid error subtracted), over-approximates that region; if start and goal lie
in different 8-connected components of it, no path exists, whatever the turning radius. The converse does
not hold (a gap may be too narrow for the rectangle or too tight for the turning radius); the planner's
time budget catches those.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from services.bus.schemas.navigation import REASON_GOAL_ENCLOSED
from services.errors import InfeasibleError
from services.navigation.geometry import FootprintChecker, Pose2D

_EIGHT_CONNECTED = np.ones((3, 3), dtype=bool)


def check_reachable(checker: FootprintChecker, start: Pose2D, goal: Pose2D) -> None:
    """Raise InfeasibleError naming the enclosing obstacles when ``goal`` is provably unreachable.

    Both poses must already be collision-free (their grid cells are then in the free region).
    """
    free = checker.reachable_mask()
    labels, _ = ndimage.label(free, structure=_EIGHT_CONNECTED)
    i_s, j_s = checker.cell_of(start.x_m, start.y_m)
    i_g, j_g = checker.cell_of(goal.x_m, goal.y_m)
    if labels[i_s, j_s] == labels[i_g, j_g] and labels[i_g, j_g] != 0:
        return
    goal_region = labels == labels[i_g, j_g]
    rim = ndimage.binary_dilation(goal_region, structure=_EIGHT_CONNECTED) & ~goal_region
    names: set[str] = set()
    reach = checker.r_in + 2.0 * checker.resolution_m
    for i, j in zip(*np.nonzero(rim), strict=True):
        x, y = checker.node_xy(int(i), int(j))
        names.update(checker.obstacles_near(x, y, reach))
    edges = (goal_region[0, :], goal_region[-1, :], goal_region[:, 0], goal_region[:, -1])
    touches_bounds = any(bool(edge.any()) for edge in edges)
    area_m2 = float(goal_region.sum()) * checker.resolution_m**2
    enclosing = sorted(names)
    where = " and the scene bounds" if touches_bounds else ""
    raise InfeasibleError(
        f"goal ({goal.x_m:.2f}, {goal.y_m:.2f}) is enclosed by {enclosing}{where}: no gap wider than the "
        f"robot's footprint ({2 * checker.r_in:.2f} m incl. margin) connects it to the start "
        f"({start.x_m:.2f}, {start.y_m:.2f}); move an obstacle or choose another goal",
        {
            "reason": REASON_GOAL_ENCLOSED,
            "enclosing_obstacles": enclosing,
            "touches_bounds": touches_bounds,
            "goal_region_area_m2": area_m2,
            "footprint_inradius_m": checker.r_in,
        },
    )
