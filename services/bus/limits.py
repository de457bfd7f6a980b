"""Bounds of request fields, as msgspec ``Meta`` constraints the codec checks before any handler runs.

One place for the limits every schema module uses (issue 16): a request outside them gets
``invalid_request`` naming the field path and the bound (``Expected `float` <= 100.0 - at
`$.goal_pose[0]```), so no planner ever sees an absurd number, an unbounded list or a budget of a
year. They bound the *work* a request can ask for; the planners keep their own, finer checks
(feasibility, the documented domain of each option) and name the field in theirs.

The numbers are wide: this robot lives in a room (coordinates within 100 m), walks at most
:data:`MAX_STEPS` steps in one request and plans for at most :data:`MAX_BUDGET_S` seconds.
"""

from __future__ import annotations

import math
from typing import Annotated

from msgspec import Meta

from services.errors import InvalidRequestError

#: Any world coordinate [m]; the scenes span a few metres.
MAX_COORD_M = 100.0
#: Any angle, unwrapped [rad].
MAX_ANGLE_RAD = 100.0
#: A distance, radius, size or height of an object or a margin of a planner [m].
MAX_SIZE_M = 20.0
#: A tolerance or a margin of a planner [m or rad].
MAX_TOLERANCE = 1.0
#: A planning time budget [s].
MAX_BUDGET_S = 60.0
#: A duration in a walk or motion (a phase, a hold, a blend) [s].
MAX_PHASE_S = 30.0
#: Footsteps of one walk, obstacles of one scene, tasks of one plan, objects named in one request.
MAX_STEPS = 200
MAX_OBSTACLES = 200
MAX_TASKS = 16
MAX_NAMES = 64
#: Characters of a name (object, model, scene, joint, camera).
MAX_NAME_CHARS = 128
#: Iterations of a numerical solver in one request.
MAX_ITERATIONS = 100_000
#: Seeds are unsigned 32-bit (numpy and OMPL accept them all).
MAX_SEED = 2**32 - 1
#: Regularization of a least-squares solver (Levenberg-Marquardt mu_0, or its growth with the residual).
MAX_DAMPING = 100.0
#: Iterations a solver may add after it stopped (polishing).
MAX_POLISH_ITERATIONS = 1000
#: Image sides [px] (renders and snapshots).
MAX_IMAGE_PX = 2048
#: Configurations of one forward-kinematics request (120 s of motion at 5 ms), and frame poses in its
#: reply (configurations x frames): the reply's size is bounded before any work starts.
MAX_CONFIGURATIONS = 24_000
MAX_FRAME_POSES = 100_000


def check_budget(value_s: float, name: str) -> None:
    """InvalidRequestError naming ``name`` unless 0 < ``value_s`` <= :data:`MAX_BUDGET_S` (a configured
    budget)."""
    if not (math.isfinite(value_s) and 0.0 < value_s <= MAX_BUDGET_S):
        raise InvalidRequestError(f"{name} must be within 0 and {MAX_BUDGET_S:.0f} s, got {value_s}")


Coord = Annotated[float, Meta(ge=-MAX_COORD_M, le=MAX_COORD_M, description="world coordinate [m]")]
Angle = Annotated[float, Meta(ge=-MAX_ANGLE_RAD, le=MAX_ANGLE_RAD, description="angle [rad]")]
Size = Annotated[float, Meta(ge=0.0, le=MAX_SIZE_M, description="non-negative length [m]")]
PositiveSize = Annotated[float, Meta(gt=0.0, le=MAX_SIZE_M, description="positive length [m]")]
Tolerance = Annotated[float, Meta(gt=0.0, le=MAX_TOLERANCE, description="tolerance [m or rad]")]
Margin = Annotated[float, Meta(ge=0.0, le=MAX_TOLERANCE, description="margin [m or rad]")]
Fraction = Annotated[float, Meta(gt=0.0, le=1.0, description="in (0, 1]")]
Gain = Annotated[float, Meta(gt=0.0, le=1000.0, description="positive gain")]
Budget = Annotated[float, Meta(gt=0.0, le=MAX_BUDGET_S, description="wall-clock budget [s]")]
Phase = Annotated[float, Meta(ge=0.0, le=MAX_PHASE_S, description="duration [s]")]
Iterations = Annotated[int, Meta(ge=0, le=MAX_ITERATIONS)]
Damping = Annotated[float, Meta(ge=0.0, le=MAX_DAMPING, description="damping >= 0 (0: undamped)")]
PolishIterations = Annotated[int, Meta(ge=0, le=MAX_POLISH_ITERATIONS, description="extra iterations")]
Seed = Annotated[int, Meta(ge=0, le=MAX_SEED, description="seed, unsigned 32-bit")]
Name = Annotated[str, Meta(max_length=MAX_NAME_CHARS)]
ImageSide = Annotated[int, Meta(ge=1, le=MAX_IMAGE_PX, description="image side [px]")]
Point3 = Annotated[list[Coord], Meta(min_length=3, max_length=3, description="[x, y, z] [m]")]
Pose2 = Annotated[list[Coord], Meta(min_length=3, max_length=3, description="[x, y, yaw] [m, m, rad]")]
Unit = Annotated[float, Meta(ge=-1.0, le=1.0)]
Quaternion = Annotated[list[Unit], Meta(min_length=4, max_length=4, description="[qx, qy, qz, qw]")]
Names = Annotated[list[Name], Meta(max_length=MAX_NAMES)]
#: A scene is asked for by name (a file ``<name>.yaml`` in the sim's scene folders), never by path.
SceneName = Annotated[
    str, Meta(pattern=r"^([A-Za-z0-9_][A-Za-z0-9_-]{0,63})?$", description="scene name (not a path)")
]
StepCount = Annotated[int, Meta(ge=0, le=MAX_STEPS, description="number of footsteps")]
#: Lists of names, e.g. [spot, surface] pairs of contacts.
NameLists = Annotated[list[Names], Meta(max_length=MAX_NAMES)]
