"""Walks to a goal: the footsteps of a short walk, a turn on the spot or a squared stance, made by the
walking planner within the robot's stepping bounds and checked against the map's boxes.

A goal is relative to the robot's stance now (the soles measured on ``q_start``), not a footstep list:

* :func:`walk_to_steps`: the mid-feet frame to a pose (dx, dy, dyaw) in the starting mid-feet frame,
  stepping forward, sideways and turning together (or, when that crosses the feet, walking there and
  then turning on the spot), the feet side by side at the end, each step as long as the bounds allow
  (footstep paper 000 §4 bounds, :func:`~services.walking.footsteps.fit_to_bounds`);
* :func:`turn_steps`: a turn on the spot by an angle (:func:`~services.walking.footsteps.turn_in_place`),
  a staggered stance (one foot ahead after a reaching step) squared up first (:func:`square_up`);
* :func:`square_up`: the one step that brings the rear foot beside the front one.

:func:`check_clear` is the obstacle test of these walks (the map's boxes: footprint rectangles on the
floor, world frame): the mid-feet path keeps a clearance, every landing sole keeps a margin, and a turn
on the spot needs room around the mid-feet point. Pure: no bus here (``service.py`` is the adapter).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from services.bus.schemas.walking import REASON_BLOCKED, REASON_NO_ROOM_TO_TURN
from services.errors import InfeasibleError
from services.model.geometry import segment_distance
from services.model.ground import (
    Footstep,
    FootstepBounds,
    FootstepSequence,
    Rectangle,
    SolePose,
    mid_feet,
    rectangles_overlap_depth,
    sole_corners,
    sole_pose_at,
)
from services.walking.footsteps import fit_to_bounds, footsteps_along_mid_poses, turn_in_place

#: Largest yaw of one pair of turning steps [rad]: the opening foot's bound is pi/4 (footstep paper §4).
TURN_PER_PAIR_RAD = 0.98 * math.pi / 4
#: Feet further apart than this along the heading [m], or turned apart by more [rad], are squared up
#: before a turn on the spot (whose steps are made for a square stance).
SQUARE_DX_M = 0.02
SQUARE_DYAW_RAD = math.radians(3.0)


class MapBox(NamedTuple):
    """A box of the map on the floor: its ``name`` and footprint ``rect`` (``services.model.ground``'s
    one rectangle, world frame)."""

    name: str
    rect: Rectangle

    def distance_to_point(self, x_m: float, y_m: float) -> float:
        """Horizontal distance from (x, y) to the footprint [m] (negative inside)."""
        return float(self.rect.signed_distance((x_m, y_m))[0])


def polygons_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Signed distance [m] between two convex polygons (k, 2): the gap when apart, minus the penetration
    depth when they overlap."""
    depth = rectangles_overlap_depth(a, b)
    if depth > 0.0:
        return -depth
    z = np.zeros(1)
    best = math.inf
    for i in range(len(a)):
        p0, p1 = np.concatenate([a[i], z]), np.concatenate([a[(i + 1) % len(a)], z])
        for j in range(len(b)):
            q0, q1 = np.concatenate([b[j], z]), np.concatenate([b[(j + 1) % len(b)], z])
            best = min(best, segment_distance(p0, p1, q0, q1))
    return best


def soles_on(robot: Any, q: np.ndarray) -> dict[str, SolePose]:
    """The sole poses (x [m], y [m], yaw [rad]) on the ground of a ``services.model`` robot at ``q``."""
    return {side: sole_pose_at(robot, q, side) for side in ("left", "right")}


def square_up(soles: dict[str, SolePose], limits: FootstepBounds) -> Footstep | None:
    """The step that brings the rear foot beside the front one (parallel, at their current lateral
    distance kept within the bounds), or None when the stance is already square.

    After a reaching step one foot is up to 0.22 m ahead, while ``turn_in_place`` makes its steps for
    a square stance, turning about its mid-feet point."""
    ahead = _ahead(soles)
    dyaw = abs(math.remainder(soles["left"].yaw_rad - soles["right"].yaw_rad, 2 * math.pi))
    if abs(ahead["left"] - ahead["right"]) <= SQUARE_DX_M and dyaw <= SQUARE_DYAW_RAD:
        return None
    front = max(soles, key=lambda side: ahead[side])
    rear = "left" if front == "right" else "right"
    f = soles[front]
    cf, sf = math.cos(f.yaw_rad), math.sin(f.yaw_rad)
    dx, dy = soles[rear].x_m - f.x_m, soles[rear].y_m - f.y_m
    lateral = abs(-sf * dx + cf * dy)  # the rear foot's distance to the side in the front foot's frame
    lateral = min(max(lateral, limits.dy_min_m + 0.02), limits.dy_max_m - 0.02)
    sign = 1.0 if rear == "left" else -1.0  # the left foot is on the +y side
    pose = SolePose(f.x_m - sign * lateral * sf, f.y_m + sign * lateral * cf, f.yaw_rad)
    return Footstep(side=rear, pose=pose)  # type: ignore[arg-type]


def _ahead(soles: dict[str, SolePose]) -> dict[str, float]:
    """Each sole's position [m] along the mid-feet heading."""
    yaw = mid_feet(soles["left"], soles["right"]).yaw_rad
    c, s = math.cos(yaw), math.sin(yaw)
    return {side: c * p.x_m + s * p.y_m for side, p in soles.items()}


def front_foot(soles: dict[str, SolePose]) -> str | None:
    """The foot more than ``SQUARE_DX_M`` ahead of the other along the mid-feet heading, None when the
    stance is square in that direction."""
    ahead = _ahead(soles)
    if abs(ahead["left"] - ahead["right"]) <= SQUARE_DX_M:
        return None
    return max(ahead, key=lambda side: ahead[side])


def walk_to_steps(
    soles: dict[str, SolePose],
    dx_m: float,
    dy_m: float,
    dyaw_rad: float,
    limits: FootstepBounds,
    lead: str | None = None,
    *,
    face_the_way: bool = False,
) -> FootstepSequence:
    """Footsteps that bring the mid-feet frame to (dx, dy [m], dyaw [rad]) in the starting mid-feet frame,
    the feet side by side at the end (a staggered start is evened out on the way). ``lead``: the foot
    that steps first (None: toward the side or the turn; straight back from a staggered stance, the
    front foot).

    Stepping forward, sideways and turning together; when that crosses the feet, walking there and then
    turning on the spot (:func:`turn_steps`). With ``face_the_way`` (a walk farther than
    ``FACE_THE_WAY_MIN_M``), also turning toward the goal first, walking straight to it and turning to
    the goal's heading there: of these, the walk of fewest steps (a sideways step gains at most
    dy_max - spacing, 6 cm for HRP-2, a forward one 0.22 m: fetch seed 16's 1.0 m forward, 0.5 m
    left, -32 deg took 24 steps, 12 of them turning on the spot by 2.9 deg each).

    Raises:
        InfeasibleError: no count of steps fits the bounds (:func:`fit_to_bounds`).
    """
    first = "left" if (dy_m if abs(dy_m) > 0.02 else dyaw_rad) > 0 else "right"  # lead on the way
    front = front_foot(soles)
    if dx_m < 0.0 and abs(dy_m) <= 0.02 and dyaw_rad == 0.0 and front is not None:
        # Straight back from a staggered stance: the front foot leads, so that the first weight transfer
        # goes onto the rear foot and the lifted front leg moves away from what is in front of it. With
        # the rear foot leading, the weight goes forward onto the front foot and the rear knee comes
        # forward as it lifts: fetch seed 37's right thigh (RLEG_LINK2), 3 cm from the box it had just
        # reached into, touched it.
        first = front
    first = lead or first

    def together(n: int) -> FootstepSequence:
        return _along_line(soles, dx_m, dy_m, dyaw_rad, first, n)

    goal = mid_feet(soles["left"], soles["right"]).compose(dx_m, dy_m, dyaw_rad)

    def turn_last() -> FootstepSequence:  # walk there, then turn on the spot
        return _walk_then_turn(soles, goal, limits, first)

    def straight() -> FootstepSequence:
        return fit_to_bounds(together, 2, limits, "a straight walk")

    if face_the_way and math.hypot(dx_m, dy_m) >= FACE_THE_WAY_MIN_M:
        return _fewest_steps([straight, turn_last, lambda: _facing_the_way(soles, goal, limits)])
    # turning while stepping sideways can cross the feet: then walking there first, and turning
    return _fewest_steps([straight], [turn_last])


def _fewest_steps(*groups: list[Callable[[], FootstepSequence]]) -> FootstepSequence:
    """The sequence of fewest steps of the first group with a feasible one (the first of equals);
    InfeasibleError of the last one tried when none is."""
    error: InfeasibleError | None = None
    for group in groups:
        found = []
        for make in group:
            try:
                found.append(make())
            except InfeasibleError as exc:
                error = exc
        if found:
            return min(found, key=lambda seq: len(seq.steps))
    assert error is not None
    raise error


#: A walk to a pose farther than this [m] may turn toward it first (``walk_to_steps(face_the_way=True)``).
FACE_THE_WAY_MIN_M = 0.4
#: Longest forward step [m] of a walk there before turning (and navigation's ``max_step_m``): the bounds
#: allow 0.22 m, but with the ball held ahead HRP-2's knee then needs 7.5 rad/s (limit 4; fetch seed 9,
#: 0.214 m steps facing the way to the table).
MAX_STRIDE_M = 0.20


def _fractions(n: int) -> list[float]:
    """Mid-feet fractions of a walk of ``n`` steps, the last one bringing the feet side by side."""
    return [min(k, n - 1) / (n - 1) for k in range(1, n + 1)]


def _along_line(
    soles: dict[str, SolePose], dx_m: float, dy_m: float, dyaw_rad: float, first: str, n: int
) -> FootstepSequence:
    """``n`` steps bringing the mid-feet frame evenly to (dx, dy, dyaw) of the starting mid-feet frame."""
    poses = [(f * dx_m, f * dy_m, f * dyaw_rad) for f in _fractions(n)]
    return footsteps_along_mid_poses(poses, first, left_start=soles["left"], right_start=soles["right"])


def _then_turn(walk: FootstepSequence, angle_rad: float, limits: FootstepBounds) -> FootstepSequence:
    """``walk`` followed by a turn on the spot by ``angle_rad`` where it ends (none below 1e-6 rad)."""
    if abs(angle_rad) < 1e-6:
        return walk
    left, right = walk.final_stance()
    return joined(walk, turn_steps({"left": left, "right": right}, angle_rad, limits))


def _walk_then_turn(
    soles: dict[str, SolePose], goal: SolePose, limits: FootstepBounds, first: str | None = None
) -> FootstepSequence:
    """Walk straight (the heading kept) to the mid-feet ``goal`` (world), then turn on the spot to its
    heading. A turn on the spot moves the opening foot outward (:func:`turn_in_place`) and the mid-feet
    point a few mm to cm aside: the walk aims at the goal less that shift (measured on a first try)."""
    mid = mid_feet(soles["left"], soles["right"])
    aim = goal
    for _ in range(2):
        gx, gy, _ = SolePose(aim.x_m, aim.y_m, 0.0).relative_to(mid)
        side = first or ("left" if gy > 0.02 else "right")
        walk = fit_to_bounds(
            lambda n, gx=gx, gy=gy, side=side: _along_line(soles, gx, gy, 0.0, side, n),
            max(2, math.ceil(abs(gx) / MAX_STRIDE_M) + 1),
            limits,
            "a straight walk, then a turn",
        )
        end = mid_feet(*walk.final_stance())
        whole = _then_turn(walk, math.remainder(goal.yaw_rad - end.yaw_rad, 2 * math.pi), limits)
        reached = mid_feet(*whole.final_stance())
        aim = SolePose(aim.x_m + goal.x_m - reached.x_m, aim.y_m + goal.y_m - reached.y_m, 0.0)
    return whole


def _facing_the_way(soles: dict[str, SolePose], goal: SolePose, limits: FootstepBounds) -> FootstepSequence:
    """Turn on the spot toward the mid-feet ``goal`` (world), walk straight to it, turn to its heading."""
    start = mid_feet(soles["left"], soles["right"])
    gx, gy, _ = SolePose(goal.x_m, goal.y_m, 0.0).relative_to(start)
    bearing = math.atan2(gy, gx)
    if abs(bearing) <= 1e-3:
        return _walk_then_turn(soles, goal, limits)
    turn = turn_steps(soles, bearing, limits)
    left, right = turn.final_stance()
    return joined(turn, _walk_then_turn({"left": left, "right": right}, goal, limits))


def turn_steps(soles: dict[str, SolePose], angle_rad: float, limits: FootstepBounds) -> FootstepSequence:
    """Turn on the spot by ``angle_rad`` (> 0: left) from the soles where they are: squared up first when
    one foot is ahead of the other (:func:`square_up`), then pairs of at most ``TURN_PER_PAIR_RAD``.

    Raises:
        InfeasibleError: the turn does not fit the bounds.
    """
    start = dict(soles)
    first = square_up(start, limits)
    if first is not None:
        start[first.side] = first.pose
    n_pairs = max(1, math.ceil(abs(angle_rad) / TURN_PER_PAIR_RAD))
    turn = turn_in_place(
        angle_rad,
        2 * n_pairs,
        left_start=start["left"],
        right_start=start["right"],
        sole_size_m=(limits.sole_length_m, limits.sole_width_m),
        limits=limits,
    )
    steps = (*([first] if first is not None else []), *turn.steps)
    return FootstepSequence(soles["left"], soles["right"], steps)


def back_and_turn_steps(
    soles: dict[str, SolePose],
    back_m: float,
    angle_rad: float,
    limits: FootstepBounds,
    lead: str | None = None,
) -> tuple[FootstepSequence, FootstepSequence]:
    """Straight back by ``back_m`` [m] (:func:`walk_to_steps` led by ``lead``, the feet side by side at
    the end), then a
    turn on the spot by ``angle_rad`` from there (:func:`turn_steps`): the two parts, to be checked
    each as what it is (the turn's room at the stance it starts from) and walked as one walk (one
    start, one stop: no stand-still between them).

    Raises:
        InfeasibleError: a part does not fit the bounds.
    """
    back = walk_to_steps(soles, -back_m, 0.0, 0.0, limits, lead)
    left, right = back.final_stance()
    turn = turn_steps({"left": left, "right": right}, angle_rad, limits)
    return back, turn


def joined(first: FootstepSequence, then: FootstepSequence) -> FootstepSequence:
    """``first``'s steps followed by ``then``'s (which starts where ``first`` ends): one sequence."""
    return FootstepSequence(first.left_start, first.right_start, first.steps + then.steps)


def square_steps(soles: dict[str, SolePose], limits: FootstepBounds) -> FootstepSequence:
    """The squaring step alone (an empty sequence when the stance is square)."""
    first = square_up(soles, limits)
    return FootstepSequence(soles["left"], soles["right"], (first,) if first is not None else ())


def check_clear(
    sequence: FootstepSequence,
    boxes: Sequence[MapBox],
    *,
    clearance_m: float,
    sole_margin_m: float,
    sole_size_m: tuple[float, float],
    turn_room_m: float | None = None,
    path_step_m: float = 0.05,
) -> None:
    """Check a walk against the map's ``boxes``.

    * The mid-feet point, on the straight line from the start to the end stance, keeps ``clearance_m``
      from every box, or as far as it is at the start or the end if nearer (walking up to a table, or
      away from it, is allowed; passing closer than both ends is not).
    * Every landing sole (a ``sole_size_m`` = length, width [m] rectangle) keeps ``sole_margin_m`` from
      every box (or as far as the nearest starting sole is, if nearer).
    * ``turn_room_m`` (a turn on the spot): no box nearer than this to the mid-feet point (the arms
      sweep a circle).

    Raises:
        InfeasibleError: ``details``: ``reason`` (``REASON_BLOCKED`` or ``REASON_NO_ROOM_TO_TURN`` of
            the walking schema), ``obstacle`` (its name), ``distance_m`` and ``required_m``.
    """
    if not boxes:
        return
    stances = sequence.stances()
    start = mid_feet(*stances[0])
    end = mid_feet(*stances[-1])
    length = math.hypot(end.x_m - start.x_m, end.y_m - start.y_m)
    n = max(2, math.ceil(length / path_step_m) + 1)
    start_soles = [sole_corners(p, *sole_size_m) for p in stances[0]]
    for box in boxes:
        if turn_room_m is not None:
            d = box.distance_to_point(start.x_m, start.y_m)
            if d < turn_room_m:
                raise InfeasibleError(
                    f"no room to turn on the spot: {box.name} is {d:.2f} m from the robot's mid-feet "
                    f"point (a turn needs {turn_room_m:.2f} m): step away from it first",
                    {
                        "reason": REASON_NO_ROOM_TO_TURN,
                        "obstacle": box.name,
                        "distance_m": d,
                        "required_m": turn_room_m,
                    },
                )
        ends = (box.distance_to_point(start.x_m, start.y_m), box.distance_to_point(end.x_m, end.y_m))
        need = min(clearance_m, *ends) - 0.02
        for t in np.linspace(0.0, 1.0, n):
            x, y = start.x_m + t * (end.x_m - start.x_m), start.y_m + t * (end.y_m - start.y_m)
            d = box.distance_to_point(x, y)
            if d < need:
                raise InfeasibleError(
                    f"the walk passes {d:.2f} m from {box.name} at ({x:.2f}, {y:.2f}) (it keeps "
                    f"{need:.2f} m from the map's boxes): walk around it (navigation)",
                    {"reason": REASON_BLOCKED, "obstacle": box.name, "distance_m": d, "required_m": need},
                )
        corners = box.rect.corners()
        sole_need = min(sole_margin_m, *(polygons_distance(s, corners) for s in start_soles)) - 0.005
        for i, step in enumerate(sequence.steps):
            sole = sole_corners(step.pose, *sole_size_m)
            d = polygons_distance(sole, corners)
            if d < sole_need:
                raise InfeasibleError(
                    f"step {i} ({step.side} foot) lands {d:.2f} m from {box.name} (the soles keep "
                    f"{sole_need:.2f} m from the map's boxes)",
                    {
                        "reason": REASON_BLOCKED,
                        "obstacle": box.name,
                        "distance_m": d,
                        "required_m": sole_need,
                        "step_index": i,
                    },
                )
