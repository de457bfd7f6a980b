"""Stage 2's collision check: navigation's name for :mod:`services.collision.motion`.

The 3D motion checker lives in the shared package below navigation and walking (walking checks its legs
with it, ``services/walking/sweep.py``); this module re-exports it for navigation's callers.
"""

from services.collision.motion import GROUPS as GROUPS
from services.collision.motion import RESHAPABLE_GROUPS as RESHAPABLE_GROUPS
from services.collision.motion import CollisionEvent as CollisionEvent
from services.collision.motion import MotionCheck as MotionCheck
from services.collision.motion import MotionChecker as MotionChecker
from services.collision.motion import part_group as part_group
