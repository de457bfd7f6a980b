"""The arms' floor rectangle of stage 1, measured on the robot's own collision shapes.

Stage 1 approximates the body by boxes (:class:`services.navigation.geometry.BodyModel`); the arms are the
part whose extent depends on the posture: hanging at the sides in half-sitting, ahead of the body when
holding a bar. The whole-body walk keeps the arms' posture of the starting configuration (posture task)
or holds the bar there, so :func:`with_arms_of` measures them once in that configuration.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pinocchio as pin

from services.collision.motion import part_group
from services.model.geometry import shape_points
from services.navigation.geometry import BodyModel


def arm_extents(robot: Any, q: np.ndarray) -> tuple[tuple[float, float], float, tuple[float, float]]:
    """The arms' extent at configuration ``q`` in the base frame on the floor (mid-feet point, heading):
    ((x_back, x_front) [m], half width [m] (the larger side), (z_bottom, z_top) [m])."""
    gmodel = robot.build_geometry_model("collision")
    data = robot.model.createData()
    gdata = pin.GeometryData(gmodel)
    pin.updateGeometryPlacements(robot.model, data, gmodel, gdata, q)
    x0, y0, yaw = robot.mid_feet_pose(q)
    points = []
    for i, obj in enumerate(gmodel.geometryObjects):
        if part_group(obj.name) != "arms":
            continue
        T = gdata.oMg[i]
        points.append(shape_points(obj.geometry) @ T.rotation.T + T.translation)
    P = np.vstack(points)
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = P[:, 0] - x0, P[:, 1] - y0
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    return (
        (float(lx.min()), float(lx.max())),
        float(np.abs(ly).max()),
        (float(P[:, 2].min()), float(P[:, 2].max())),
    )


def with_arms_of(body: BodyModel, robot: Any, q: np.ndarray) -> BodyModel:
    """``body`` with its arms' rectangle measured at configuration ``q`` (symmetric width: the larger
    side)."""
    (x_back, x_front), half_width, z_range = arm_extents(robot, q)
    return dataclasses.replace(
        body, arms_width_m=2.0 * half_width, arms_z_range_m=z_range, arms_x_range_m=(x_back, x_front)
    )
