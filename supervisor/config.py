"""The supervisor's tunables: one frozen dataclass, defaults in code, optional YAML override.

``humanoid run|console|fetch --config FILE`` reads the ``supervisor:`` section of FILE (the same file as
the ``bus:`` section); unknown keys and values of the wrong type are refused at start-up, naming them::

    supervisor:
      goto_distance_m: 0.45
      far_m: 2.5
      carry_m: [0.25, 0.22, 0.85]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from services.bus.config import load_section
from services.bus.schemas import reaching as reach_msg
from services.errors import InvalidRequestError

FAST_ARM_MOTIONS = ("raise", "lift", "carry", "withdraw")
"""The unguarded arm motions ``SupervisorConfig.fast_arm_motions`` may name."""


@dataclass(frozen=True)
class SupervisorConfig:
    """Tunables of the supervisor's actions (lengths [m], times [s]).

    Locomotion:
        goto_distance_m: ``goto OBJECT`` stands this far from the object's face by default;
        clearance_m: before turning or walking away, the robot steps back until the objects seen are
            this far from its mid-feet point; max_step_back_m: by at most this much at once;
            room_margin_m: that far and this much more; straight_back_deg: a way out within this
            many [deg] of straight back is taken as straight back (before a turn: the step back and
            the turn are then one walk of ``walking/goal``); min_turn_deg: a turn asked smaller than
            this [deg] is not made;
        goto_farther_m: when navigation finds no free place to stand at the distance asked from an
            object (its map box is a rough estimate), it is asked again this much farther [m], each
            in turn (reaching steps the rest of the way);
        far_m, near_m: an object farther than far_m is first approached to near_m and localized again
            (near_face_m from a free face of it when there is no walk to the pose near_m short of it,
            and not at all when there is none to a face either);
        retry_budget_s, retry_turning_radius_m: when navigation finds no path in its default budget,
            the second search's budget and turning radius (the first's is navigation's 0.5 m);
        walk_double_support_s: double support between the steps of a walk, 0.2 s. With the sim's
            stabilizer (``sim/stabilizer.py``, off by default) 0.1 s had 0 falls in a fall study of 100
            fetch-like walks (services/walking/README.md), but the stabilizer failed fetch seed 6
            (session 11). Open loop, 0.1 s passed session 9's fall study
            (``scripts/walk_timing_study.py``: 0 falls in 25 fetch-like walks at 0.7 / 0.1 s) but not
            the fetch: seeds 16 and 43 fell (tilt 28.7-28.9 deg, at
            the end of a 24-step straight walk and early in a 21-step one), seed 16 deterministically,
            and at 0.2 s seed 16 succeeds (session 9's notes); 0.3 s before session 8. The cause
            (session 10, services/walking/README.md): touchdowns 30-90 ms off their planned time eat the
            0.1 s, each weight transfer becomes a jolt that feeds the robot's rocking from foot to foot
            (steps in place and sideways most), which nothing damped in open loop.
    Manipulation:
        last_steps: before a reach or a put, ask ``footsteps/plan`` (paper 000 §7: the fine-tuner of
            the end of the approach) for the last steps, within last_steps_max steps and
            last_steps_budget_s of planning, and walk them (reaching still steps if the object moved);
            last_steps_posture: the approaches ("grasp", "put") in which reaching then brings the hand
            above the object (the held object above the place) turned as in the final posture
            footsteps/plan planned with those steps, without stepping (the footstep planner decided
            the stance), and lowers it keeping that orientation (position only where reaching refuses
            it, or where such an approach to the object touched something before). The put only by
            default: in the grasp that orientation brought the wrist or forearm onto the neighbouring
            ball (or the target ball) on the way above it in fetch seeds 6 and 12, three times each,
            where the position-only approach grasps (perception does not see the other balls);
        nearer_beyond_m, nearer_m: when footsteps/plan finds no last steps to a point farther than
            nearer_beyond_m from the robot, navigation first walks to nearer_m short of it, facing it
            (when that pose is not free: goto_distance_m from the face of the place, or of the
            object's support), checked against the map (reaching's stepping does not know the map),
            and the last steps are planned again from there;
        back_off_m: after a collision, the touching hand moves this far back and up;
        put_height_m: the object is brought this high above the estimated top of the place, then
            lowered until it touches; put_highest_m, put_lowest_m: bounds of a place's top height (the
            estimate is capped at the first, the object is lowered down to the second at most);
            put_depth_m: and at most this far; put_inside_m: the release point is this far inside the
            place's near face, moved when a ball seen on the place lies nearer than put_clear_m to it
            or to the forearm's way over the place (put_forearm_m from the point toward the robot):
            to the nearest point of the place's top (put_edge_margin_m inside its rectangle) clear of
            them (layout table_to_box: the forearm lowered onto a ball beside the point);
            put_retry_shift_m: after a put that touched nothing, the next release
            point is this far at most from the first, toward the middle of the place's silhouette;
            put_edge_deg, put_edge_shift_m, put_edge_tries: a lowered object whose every contact with
            the place is more than put_edge_deg [deg] off straight below the hand's grasp frame
            touched an edge on its side (it hangs over the edge and would fall off): it is raised,
            moved put_edge_shift_m toward the contacts and lowered again, at most put_edge_tries times
            (an arm touching the place instead of the object: moved that far further along the
            approach, once); put_view_m: after a put that touched nothing, navigation walks back to
            this far from the point that missed and perception maps the place again from there (its
            whole outline in view, beyond perception's footprint depth);
        fast_arm_motions: the unguarded arm motions (no object near the hand's path) that reaching
            times with fast_arm_speed_m_s (the hand's mean speed at most [m/s]), fast_arm_min_s (the
            shortest motion [s]) and fast_arm_hold_s (the final hold [s]) instead of its default, the
            paper's slow reach (0.2 m/s, at least 1.4 s, 0.3 s hold): reaching slows them down where a
            joint would be too fast, and never steps for them. "raise": the hand raised before
            reaching above an object, the held object raised before a put (and again after a put
            that touched nothing); "carry": the held object brought to the carry point; "withdraw":
            the emptied hand's lift and carry after a put; "lift": the grasped object lifted off its
            support (off by default: its neighbours are near). The guarded motions near objects
            (above an object, down onto it, the put) keep the default timing (session 8: all at
            0.25 m/s and 1.0 s, two fetches failed in the hand's part);
        approach_m: the hand first goes this far above a reach or put point, then down;
        lift_m: a grasped object (or an emptied hand) is raised by this first;
        carry_m: (forward, lateral, height) of the carry point in front of the chest;
        raise_ahead_m: a hand below the approach height is first raised at least this far ahead of
            the mid-feet point;
        raise_box_margin_m: that raise goes straight up first, then forward, when its straight line
            comes over the map's box of the object's support less than this far [m] above its top;
        upright_hand: ask reaching for the grasp frame upright along the heading (fingers down, jaws
            sideways) for the two last motions of a reach (above the object, then down onto it): no
            finger then reaches past the object onto a neighbour (a hand pointing forward swept the
            ball beyond the target, fetch seeds 6 and 12); where reaching refuses it (its joint-speed
            or end-effector criteria), position only; the other motions are position only. Off by
            default: in the fetch runs tried reaching refused it (an arm joint at 52-57 % of its
            velocity limit against 50 %; in two motions, its end-effector criterion).
        turn_piece_deg: fingers down refused in one motion: in motions turning the hand by at most
            this much [deg] each (at least two).
        felt_radius_m, felt_clear_deg, felt_turns_deg: a hand that touched something perception does
            not know (a ball beside the target: no model of it) within felt_radius_m of the next reach
            point makes the robot walk around that point by the smallest of felt_turns_deg [deg] that
            puts the touched points felt_clear_deg [deg] off its direction to the point (the fingers
            point that way, past the object); jaws_turns_deg, jaws_planned: with such points near it
            (they can lie beside the wrist too: fetch seed 37, where no walk around clears them) the
            hand goes down onto it fingers down, its yaw the heading turned by the one of
            jaws_turns_deg [deg] (either way) that puts the touched points nearest the hand's x axis,
            clear of the jaws (empty: off). With jaws_planned that hand (above the object, fingers down
            at that yaw) is a task of footsteps/plan, which chooses the stance for it, and reaching
            executes the planned posture from there without stepping (above the object, then straight
            down); none found, or reaching refusing it: reaching is asked for it in motions of at most
            turn_piece_deg, then position only as without it (fetch5: without the planned stance
            reaching refused it on seed 37); jaws_step_region_scale: footsteps/plan's step region
            scaled by this for that stance (steps away from the corners of the bounds: walking refused
            a 6-step plan there, a knee at 11 rad/s); relocalized_jump_m: before that, an object seen
            again farther than this [m] from where the last lowering aimed, less confidently, is taken
            where it was aimed; jaws_lag_m: reaching then accepts the hand this far [m] behind its
            reference on the way to that planned posture (its default, the paper's 4e-5 m, is a
            trigger for stepping; the hand 0.24 mm behind refused it on seed 37); from that stance
            reaching does not step (seed 6: 8 steps into the box). Of that hand and the hand turned
            half a turn round (the jaws' line is the same), the first stance from whose final
            posture reaching carries the object and walking steps back jaws_step_back_m [m] is kept
            (dry runs; none: as without it). jaws_free_yaw: before those two, the yaw is left to
            footsteps/plan (an orient task with free_yaw, the hand on the object: the gripper's rows
            against the spheres turn the jaws clear of them), its stance kept under the same checks
            and when its final posture has the fingers within jaws_tilt_deg [deg] of down; the yaw
            then comes from that posture. jaws_lag_m also bounds the hand's lag in the fingers-down
            motion from a stance planned without the jaws. felt_obstacle_radius_m: the felt
            points near an object to grasp also go to footsteps/plan as spheres of this radius [m]
            that the arm (forearm, upper arm) keeps out of, with the object itself.
        hand_way_deg, hand_way_gap_m: a reach or grasp whose script line names no hand uses the right
            one unless an object beside the target on the map (a ball seen, a point felt) lies on its
            side of the approach, between hand_way_deg = (low, high) [deg] off it, with a surface gap
            under hand_way_gap_m [m], and none on the left's: then the left (fetch seeds 6 and 37: the
            right gripper came down on a ball 3.1 / 1.6 cm beside the target, 34-58 deg right of the
            approach; seeds 4 and 12 grasped with 3.6 / 4.4 cm).
        floor_margin_m: an object whose bottom as seen (centre less radius) is within this [m] of the
            floor rests on it: a reach refused from near it is final (``out_of_reach``); higher, on
            something not mapped (a table not seen yet), the refusal is retried after a fresh look.
        grasp_clearance_m: the hand comes down onto an object with its centre this far [m] from
            where it ends held (against the fixed finger), toward the jaws' middle (never past it):
            the closing finger pushes it the rest of the way (fetch seed 46: lowered against the fixed
            finger, the ball seen 1.5 mm smaller than it is was rolled 2.2 cm away).
    Perception and remedies:
        recentre_fraction: an object seen farther than this fraction of the half-width from the image
            centre is looked at and localized again;
        search_viewpoints, search_aside_margin_m: an object not seen anywhere around (head scans,
            turning on the spot) is looked for again from at most this many viewpoints stepped aside
            past the objects on the map that may hide it (both sides of each, nearest first), the
            sight line passing this far [m] beside each (``localize``; 0: never);
        mapped_margin_m: a contact farther than this from every mapped box hit something the map lacks;
        wait_service_s: how long ``wait_service`` waits for a restarted service's liveliness token;
        plan_timeout_s: how long a planner request may take.
    """

    goto_distance_m: float = 0.4
    clearance_m: float = 0.6
    max_step_back_m: float = 0.45
    room_margin_m: float = 0.05
    straight_back_deg: float = 15.0
    min_turn_deg: float = 2.0
    goto_farther_m: tuple[float, ...] = (0.15, 0.3)
    far_m: float = 2.2
    near_m: float = 1.8
    near_face_m: float = 1.0
    retry_budget_s: float = 4.0
    retry_turning_radius_m: float = 0.3
    walk_double_support_s: float = 0.2
    last_steps: bool = True
    last_steps_max: int = 6
    last_steps_budget_s: float = 5.0
    last_steps_posture: tuple[str, ...] = ("put",)
    nearer_beyond_m: float = 1.0
    nearer_m: float = 0.6
    back_off_m: float = 0.08
    put_height_m: float = 0.12
    put_highest_m: float = 0.95
    put_lowest_m: float = 0.4
    put_depth_m: float = 0.35
    put_inside_m: float = 0.15
    put_retry_shift_m: float = 0.35
    put_clear_m: float = 0.15
    put_forearm_m: float = 0.2
    put_edge_margin_m: float = 0.1
    put_edge_deg: float = 45.0
    put_edge_shift_m: float = 0.12
    put_edge_tries: int = 2
    put_view_m: float = 1.6
    fast_arm_motions: tuple[str, ...] = ("raise", "carry", "withdraw")
    fast_arm_speed_m_s: float = 0.4
    fast_arm_min_s: float = 0.6
    fast_arm_hold_s: float = 0.15
    approach_m: float = 0.12
    lift_m: float = 0.1
    carry_m: tuple[float, float, float] = (0.25, 0.22, 0.85)
    raise_ahead_m: float = 0.2
    raise_box_margin_m: float = 0.1
    upright_hand: bool = False
    turn_piece_deg: float = 35.0
    felt_radius_m: float = 0.3
    felt_clear_deg: float = 60.0
    felt_turns_deg: tuple[float, ...] = (30.0, 45.0, 60.0)
    jaws_turns_deg: tuple[float, ...] = (15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
    jaws_planned: bool = True
    jaws_step_region_scale: float = 0.8
    relocalized_jump_m: float = 0.05
    jaws_lag_m: float = 0.001
    jaws_step_back_m: float = 0.15
    jaws_free_yaw: bool = True
    jaws_tilt_deg: float = 10.0
    felt_obstacle_radius_m: float = 0.03
    hand_way_deg: tuple[float, float] = (15.0, 90.0)
    hand_way_gap_m: float = 0.035
    floor_margin_m: float = 0.03
    grasp_clearance_m: float = 0.01
    recentre_fraction: float = 0.4
    search_viewpoints: int = 2
    search_aside_margin_m: float = 0.5
    mapped_margin_m: float = 0.1
    wait_service_s: float = 30.0
    plan_timeout_s: float = 120.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if isinstance(value, float) and not value >= 0.0:
                raise InvalidRequestError(f"supervisor config: {name} must be >= 0, got {value}")
        if self.search_viewpoints < 0:
            raise InvalidRequestError(
                f"supervisor config: search_viewpoints must be >= 0, got {self.search_viewpoints}"
            )
        if self.near_m >= self.far_m:
            raise InvalidRequestError(
                f"supervisor config: near_m ({self.near_m} m) must be below far_m ({self.far_m} m)"
            )
        unknown = set(self.last_steps_posture) - {"grasp", "put"}
        if unknown:
            raise InvalidRequestError(
                f"supervisor config: last_steps_posture takes 'grasp' and 'put', got {sorted(unknown)}"
            )
        unknown = set(self.fast_arm_motions) - set(FAST_ARM_MOTIONS)
        if unknown:
            raise InvalidRequestError(
                f"supervisor config: fast_arm_motions takes {list(FAST_ARM_MOTIONS)}, got {sorted(unknown)}"
            )
        low, high = reach_msg.MIN_DURATION_RANGE_S
        for name, value, ok, bounds in (
            (
                "fast_arm_speed_m_s",
                self.fast_arm_speed_m_s,
                0.0 < self.fast_arm_speed_m_s <= reach_msg.MAX_HAND_SPEED_M_S,
                f"(0, {reach_msg.MAX_HAND_SPEED_M_S}]",
            ),
            ("fast_arm_min_s", self.fast_arm_min_s, low <= self.fast_arm_min_s <= high, f"[{low}, {high}]"),
            (
                "fast_arm_hold_s",
                self.fast_arm_hold_s,
                0.0 <= self.fast_arm_hold_s <= reach_msg.MAX_FINAL_HOLD_S,
                f"[0, {reach_msg.MAX_FINAL_HOLD_S}]",
            ),
        ):
            if not ok:
                raise InvalidRequestError(
                    f"supervisor config: {name} must be in {bounds} (reaching's bounds), got {value}"
                )
        if not all(extra >= 0.0 for extra in self.goto_farther_m):
            raise InvalidRequestError(
                f"supervisor config: goto_farther_m must be >= 0 m, got {list(self.goto_farther_m)}"
            )
        if len(self.carry_m) != 3:
            raise InvalidRequestError("supervisor config: carry_m must be [forward, lateral, height] m")
        for name, value, most in (
            ("straight_back_deg", self.straight_back_deg, 90.0),  # beyond 90 every way out is "back"
            ("min_turn_deg", self.min_turn_deg, 180.0),
        ):
            if value > most:
                raise InvalidRequestError(f"supervisor config: {name} must be <= {most:g} deg, got {value}")

    def arm_timing(self, motion: str) -> dict[str, float]:
        """The ``reaching/reach`` timing fields of the arm ``motion`` (one of ``FAST_ARM_MOTIONS``):
        the fast ones' when it is in ``fast_arm_motions``, else none (reaching's default)."""
        if motion not in FAST_ARM_MOTIONS:
            raise ValueError(f"unknown arm motion {motion!r}; known: {list(FAST_ARM_MOTIONS)}")
        if motion not in self.fast_arm_motions:
            return {}
        return {
            "hand_speed_m_s": self.fast_arm_speed_m_s,
            "min_duration_s": self.fast_arm_min_s,
            "final_hold_s": self.fast_arm_hold_s,
        }


def load_supervisor_config(path: str | Path | None) -> SupervisorConfig:
    """Defaults, overridden by the ``supervisor:`` section of the YAML file ``path`` (if given)."""
    return load_section(path, "supervisor", SupervisorConfig)
