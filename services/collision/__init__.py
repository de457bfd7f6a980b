"""Obstacles and the 3D motion check shared by the planners that walk: navigation (stages 1 and 2) and
walking (the legs' sweep of ``walking/goal``). Below both in the package order (tests/test_layering.py);
see services/collision/README.md.
"""

from services.collision.carried import BarGrip, CarriedBar
from services.collision.motion import CollisionEvent, MotionCheck, MotionChecker
from services.collision.obstacles import (
    BoxObstacle,
    CylinderObstacle,
    Obstacle,
    Scene,
    obstacle_from_msg,
    obstacle_geometry,
)

__all__ = [
    "BarGrip",
    "BoxObstacle",
    "CarriedBar",
    "CollisionEvent",
    "CylinderObstacle",
    "MotionCheck",
    "MotionChecker",
    "Obstacle",
    "Scene",
    "obstacle_from_msg",
    "obstacle_geometry",
]
