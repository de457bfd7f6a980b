"""Executing a contact plan set by set, re-planning each transition from the measured state.

A quasi-static plan played open loop by position control does not hold: the supports slide a few
centimetres under the internal forces of the closed kinematic loops (hands on the table, soles on the
floor, thighs on the seat), and a posture whose CoM is 2-4 cm inside its support then tips (the traces
in ``services/contacts/README.md``). The feedback here works at the level of the plan: after each
transition the measured configuration is read, every contact held is re-read where its spot now is,
the next witness posture is generated again for those contacts (the same posture generator as the
search, §2.2, with the planned witness as the reference posture), and the transition to it is
interpolated from the measured configuration (§3.3) and played. Errors do not accumulate: each witness
is statically stable on the supports as they are, not as they were planned.

The executor is given as callables (the sim in one process, or ``sim/execute`` over the bus), so this
module imports neither pybullet nor zenoh.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from services.contacts.interpolate import InterpolationConfig, interpolate_transition
from services.contacts.posture import PostureGenerator
from services.contacts.sets import ContactSet, contact_at
from services.ik import PostureTask

# plays (N, nq) samples every dt [s]; returns (outcome, message): outcome "completed" goes on
PlaySegment = Callable[[np.ndarray, float], tuple[str, str]]
Measure = Callable[[], np.ndarray]  # the measured configuration q (pinocchio layout, world base)
StepHook = Callable[["TransitionReport"], None]


@dataclass(frozen=True)
class TransitionReport:
    """One transition played: ``index`` (to set ``index``), the executor's ``outcome`` and ``message``
    ("infeasible": no witness from the measured supports, nothing played), whether the witness was
    generated again from the measured supports (``replanned``), what went wrong (``reason``: the
    posture generator's, or a segment still colliding after local re-planning), the largest distance
    [m] between a held contact's measured and planned place (``support_error_m``), samples played and
    the wall time of re-planning [s]."""

    index: int
    outcome: str
    message: str
    replanned: bool
    reason: str
    support_error_m: float
    samples: int
    replan_s: float


@dataclass
class ClosedLoopResult:
    """The whole run: ``outcome`` of the last transition played ("completed" when all were), its
    message, the per-transition reports, total samples and re-planning time [s]."""

    outcome: str
    message: str
    transitions: list[TransitionReport] = field(default_factory=list)
    samples: int = 0
    replan_s: float = 0.0


def measured_contacts(gen: PostureGenerator, planned: ContactSet, q: np.ndarray) -> ContactSet:
    """The contacts of ``planned`` re-read where their spots are at ``q`` (projected on their surfaces)."""
    return tuple(contact_at(gen.spots[c.spot], c.surface, gen.env, gen.spot_pose(q, c.spot)) for c in planned)


def _support_error(gen: PostureGenerator, planned: ContactSet, measured: ContactSet) -> float:
    """Largest distance [m] between the planned and measured places of the same contacts."""
    errors = [
        float(np.linalg.norm(gen.contact_pose(a).translation - gen.contact_pose(b).translation))
        for a, b in zip(planned, measured, strict=True)
    ]
    return max(errors, default=0.0)


def regenerate_witness(
    gen: PostureGenerator,
    s1_planned: ContactSet,
    s2_planned: ContactSet,
    q2_planned: np.ndarray,
    q_measured: np.ndarray,
) -> tuple[ContactSet, ContactSet, np.ndarray | None, str]:
    """(s1 measured, s2 with its held contacts measured, the new witness or None, why not): the son's
    rule of the search (§2.3): a removal keeps the removed contact as geometry with the stability on the
    rest; an addition puts the new contact (at its planned place) out of the stability."""
    s1 = measured_contacts(gen, s1_planned, q_measured)
    by_pair = {c.pair: c for c in s1}
    s2 = tuple(by_pair.get(c.pair, c) for c in s2_planned)
    added = [c for c in s2 if c.pair not in by_pair]
    geometric = s1 + tuple(added)
    stable = s1 if added else s2
    result = gen.generate(geometric, stable, q_measured, PostureTask(gen.model, q2_planned))
    if not result.ok:
        return s1, s2, None, result.reason
    return s1, s2, result.q, ""


def execute_set_by_set(
    gen: PostureGenerator,
    sets: Sequence[ContactSet],
    witnesses: Sequence[np.ndarray],
    play: PlaySegment,
    measure: Measure,
    config: InterpolationConfig | None = None,
    on_transition: StepHook | None = None,
) -> ClosedLoopResult:
    """Play the plan (``sets`` and their ``witnesses``) transition by transition, each re-planned from
    the measured state (module docstring). Stops at the first transition the executor does not
    complete. Raises InfeasibleError when a transition from the measured state cannot be interpolated."""
    config = config or InterpolationConfig()
    v_max = np.asarray(gen.robot.v_max, float)
    out = ClosedLoopResult("completed", f"played {len(sets) - 1} transitions")
    removed: ContactSet = ()
    for k in range(1, len(sets)):
        t0 = time.perf_counter()
        q1 = np.asarray(measure(), float)
        s1, s2, q2, reason = regenerate_witness(gen, sets[k - 1], sets[k], np.asarray(witnesses[k]), q1)
        error = _support_error(gen, sets[k - 1], s1)
        if q2 is None:
            # the measured supports admit no witness of the next set: stop here (the robot holds)
            message = f"transition {k} of {len(sets) - 1}: no witness from the measured state: {reason}"
            out.transitions.append(
                TransitionReport(k, "infeasible", message, False, reason, error, 0, time.perf_counter() - t0)
            )
            out.outcome, out.message = "infeasible", message
            return out
        removed_now = measured_contacts(gen, removed, q1)
        timed, _path, hit, _refined = interpolate_transition(gen, s1, q1, s2, q2, removed_now, config, v_max)
        if hit is not None and hit[0] > config.collision_tol_m:
            reason = f"segment {hit[0] * 100:.1f} cm into {hit[2]} ({hit[1]})"
        replan_s = time.perf_counter() - t0
        outcome, message = play(timed, config.dt_s)
        report = TransitionReport(k, outcome, message, True, reason, error, len(timed), replan_s)
        out.transitions.append(report)
        out.samples += len(timed)
        out.replan_s += replan_s
        if on_transition is not None:
            on_transition(report)
        removed = tuple(c for c in sets[k - 1] if c not in sets[k])
        if outcome != "completed":
            out.outcome, out.message = outcome, f"transition {k} of {len(sets) - 1}: {message}"
            return out
    return out
