"""Footstep planning as inverse kinematics: Algorithm 1 (section 5.1) and the start-foot choice
(section 5.2) of the footstep paper (Kanoun, Laumond, Yoshida).

:func:`plan_footsteps` is the entry point: request in, :class:`FootstepPlanResult` out, or
:class:`InfeasibleError` with the residuals when the goal cannot be met within the budget.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from services.bus.schemas.common import START_SOLE_MAX_HEIGHT_M, START_SOLE_MAX_TILT_RAD
from services.bus.schemas.footsteps import (
    REASON_MAX_ITERATIONS,
    REASON_MAX_STEPS,
    REASON_SOLVED,
    REASON_STALLED,
    REASON_STEP_CAP,
    REASON_TIME_BUDGET,
)
from services.errors import InfeasibleError, InvalidRequestError, RequestTimeoutError
from services.footsteps.chain import Stance, VirtualChain
from services.footsteps.geometry import same_pose
from services.footsteps.problem import build_levels, joint_limits, robot_rest
from services.footsteps.request import (
    FootstepPlanRequest,
    FootstepPlanResult,
    PlannedFootstep,
    PlanTrace,
    TaskResidual,
)
from services.ik.solver import HierarchicalSolver, SolverConfig
from services.model import FootstepBounds, RobotModel, load_robot
from services.model.ground import sole_pose_of
from services.walking.footsteps import Side, SolePose

CONSTRAINT_TOL = 1e-3  # level-0 value (eqs. 5-6) accepted in a solution [m, rad]
FLAT_TOL_M = START_SOLE_MAX_HEIGHT_M  # q_start: soles within this of the ground
FLAT_TOL_RAD = START_SOLE_MAX_TILT_RAD  # q_start: soles within this of horizontal
# Each level's QP by the dual active-set method (services.ik.active_set): the same optimum as
# proxsuite's, but bitwise reproducible, so that identical requests give identical plans (the
# threshold decisions of Algorithm 1 amplify 1e-16 differences into different step counts).
SOLVER_CONFIG = SolverConfig(qp_method="dual_active_set")
# Solvers (with their pinocchio data, whose allocation grows as nv^3: ~8 ms at 12 steps) are kept per
# chain structure and bounds, per thread: a request reuses those of the previous ones.
SOLVER_CACHE_SIZE = 24
_local = threading.local()


def _robot_data(robot: RobotModel) -> pin.Data:
    """This thread's pinocchio data of ``robot`` (kept: allocating one costs a fraction of a millisecond;
    every use recomputes the kinematics it reads)."""
    cache: dict[int, tuple[RobotModel, pin.Data]] | None = getattr(_local, "robot_data", None)
    if cache is None:
        cache = _local.robot_data = {}
    hit = cache.get(id(robot))
    if hit is None or hit[0] is not robot:
        hit = cache[id(robot)] = (robot, robot.new_data())  # (the robot is kept: its id stays unique)
    return hit[1]


def _solver_for(chain: VirtualChain, request: FootstepPlanRequest, dq_max: float) -> HierarchicalSolver:
    """The hierarchical solver of ``chain`` with the request's joint limits and per-iteration bound
    (cached; the solver holds no state between solves that changes its results)."""
    cache: OrderedDict | None = getattr(_local, "solvers", None)
    if cache is None:
        cache = _local.solvers = OrderedDict()
    key = (chain.key, id(chain.model), request.options.joint_margin_rad, dq_max)
    solver = cache.get(key)
    if solver is not None and solver.model is chain.model:
        cache.move_to_end(key)
        return solver
    q_lower, q_upper = joint_limits(chain, request)
    solver = HierarchicalSolver(chain.model, q_lower, q_upper, dq_max=dq_max, config=SOLVER_CONFIG)
    cache[key] = solver
    while len(cache) > SOLVER_CACHE_SIZE:
        cache.popitem(last=False)
    return solver


@dataclass
class _Outcome:
    """Where Algorithm 1 stopped for one front-foot choice."""

    front_side: Side
    chain: VirtualChain
    q_tilde: np.ndarray
    values: np.ndarray  # task values at q_tilde
    constraint_value: float
    solved: bool
    reason: str
    iterations: int
    steps_added_at: list[int]
    history_values: list[np.ndarray] = field(default_factory=list)
    history_footprints: list[tuple[tuple[str, float, float, float], ...]] = field(default_factory=list)
    history_q: list[np.ndarray] = field(default_factory=list)


class _Budget:
    def __init__(self, seconds: float) -> None:
        self.deadline = time.perf_counter() + seconds

    def expired(self) -> bool:
        return time.perf_counter() > self.deadline


def initial_stance(robot: RobotModel, q_start: np.ndarray) -> Stance:
    """Both soles of ``q_start`` as footprints; InvalidRequestError if they are not flat on the ground."""
    data = _robot_data(robot)
    poses = {}
    for side in ("left", "right"):
        T = robot.sole_pose(q_start, side, data)
        z_axis = T.rotation[:, 2]
        tilt = math.acos(max(-1.0, min(1.0, float(z_axis[2]))))  # an upside-down sole gives -1 - eps
        if abs(T.translation[2]) > FLAT_TOL_M or tilt > FLAT_TOL_RAD:
            raise InvalidRequestError(
                f"q_start: the {side} sole must be flat on the ground (z = {T.translation[2]:.4f} m, tilt "
                f"{math.degrees(tilt):.2f} deg); the planner starts from a "
                "double support stance"
            )
        poses[side] = sole_pose_of(T)
    return Stance(poses["left"], poses["right"])


class _Algorithm1:
    """Algorithm 1 on one front-foot choice, from a chain state, with a shared time budget."""

    def __init__(self, request: FootstepPlanRequest, budget: _Budget) -> None:
        self.request = request
        self.budget = budget
        self.tolerances = np.array([t.tol() for t in request.tasks])
        self.required = np.isfinite(self.tolerances)
        self.has_objective = not bool(np.all(self.required))
        self.epsilons = np.array([t.eps() for t in request.tasks])
        self.alpha = request.options.alpha
        self.n_initial = max(1, request.initial_steps)
        self.dq_max = request.options.dq_max / request.options.alpha

    def _setup(self, chain: VirtualChain, held: list[tuple[int, np.ndarray]]) -> None:
        self.chain = chain
        # The front foot belongs to the initial structure: held while no footstep has been added (a
        # step that no task needs is then not taken); once the chain grows, holding it next to the
        # root foot would only fight the added steps.
        self.levels = build_levels(chain, self.request, held, hold_front=chain.n_steps <= self.n_initial)
        self.solver = _solver_for(chain, self.request, self.dq_max)
        self.solver.reset()  # (its QP warm starts come from this chain's iterations only)
        self.bound_q = self.solver.bound_q_idx
        self.q_lo = self.solver.q_lower[self.bound_q]
        self.q_hi = self.solver.q_upper[self.bound_q]

    def _evaluate(self, q: np.ndarray):
        systems = self.solver.evaluate(self.levels, q)
        n = len(self.request.tasks)
        values = np.array([systems[1 + i].value for i in range(n)])
        return systems, values, systems[0].value

    def _step(self, systems, q: np.ndarray) -> np.ndarray:
        dq = self.solver.solve_systems(self.levels, systems, q, self.alpha)
        q = pin.integrate(self.chain.model, q, self.alpha * dq)
        q[self.bound_q] = np.clip(q[self.bound_q], self.q_lo, self.q_hi)
        return q

    def _record(self, out: _Outcome, q: np.ndarray, values: np.ndarray) -> None:
        if not self.request.record_trace:
            return
        out.history_values.append(values.copy())
        fps = [
            (s, p.x_m, p.y_m, p.yaw_rad)
            for s, p in zip(self.chain.sides, self.chain.footprint_poses(q), strict=True)
        ]
        data = self.solver.data  # holds the kinematics of q (just evaluated)
        front = self.chain.front_footprint(data)
        fps.append((self.chain.front_side, front.x_m, front.y_m, front.yaw_rad))
        out.history_footprints.append(tuple(fps))
        out.history_q.append(self.chain.robot_q_world(q))

    def _stalled(self, before: np.ndarray, after: np.ndarray) -> bool:
        """Eq. (15) fails for every task: V_i^(p-1) - V_i^(p) < epsilon_i for all i.

        The paper asks epsilon_i < lambda V_i ("the threshold epsilon_i for a task T_i is to be chosen
        less than lambda V_i^(p)"); a constant epsilon_i breaks this near convergence, where the
        geometric decrease alpha lambda V_i gets small, and would add a step to a task about to be
        solved. The threshold used is therefore min(epsilon_i, relative_epsilon alpha lambda V_i)
        (``options.relative_epsilon``, 0.3; ``math.inf``: epsilon_i as written).
        A task already within its tolerance cannot be expected to decrease: it counts as stalled.
        """
        opts = self.request.options
        eps = self.epsilons
        if math.isfinite(opts.relative_epsilon):
            eps = np.minimum(eps, opts.relative_epsilon * self.alpha * opts.gain * before)
        return bool(np.all((before - after < eps) | (after <= self.tolerances)))

    def _solved(self, values: np.ndarray, constraint_value: float) -> bool:
        """Algorithm 1 line 7, "all tasks solved": every task within its tolerance and the constraints
        met. An objective (a task without tolerance, e.g. the rest posture) is never "solved": the
        algorithm keeps adding steps for it until one does not help (lines 17-18)."""
        return bool(
            not self.has_objective
            and np.all(values <= self.tolerances)
            and constraint_value <= CONSTRAINT_TOL
        )

    def success(self, values: np.ndarray, constraint_value: float) -> bool:
        """The required tasks (finite tolerance) within tolerance and the constraints met."""
        req = self.required
        return bool(np.all(values[req] <= self.tolerances[req]) and constraint_value <= CONSTRAINT_TOL)

    def run(
        self,
        chain: VirtualChain,
        q: np.ndarray,
        iterations: int = 0,
        out: _Outcome | None = None,
        held: list[tuple[int, np.ndarray]] | None = None,
        step_cap: int | None = None,
    ) -> _Outcome:
        """Algorithm 1 from (chain, q); ``held``: footprints of an initial guess held at their place;
        ``step_cap``: stop (reason "step_cap") instead of growing beyond that many steps."""
        held = list(held or [])
        self._setup(chain, held)
        systems, values, cval = self._evaluate(q)
        if out is None:
            out = _Outcome(chain.front_side, chain, q, values, cval, False, "", iterations, [])
            self._record(out, q, values)
        grow = False
        while True:
            if grow:
                grow = False
                if self.chain.n_steps >= self.request.max_steps:
                    reason = REASON_MAX_STEPS
                    break
                if step_cap is not None and self.chain.n_steps >= step_cap:
                    reason = REASON_STEP_CAP
                    break
                # Line 15: add a footstep at the root of the chain; the world state is unchanged.
                chain, q = self.chain.with_root_footprint(q)
                if chain.n_footprints > self.chain.n_footprints:
                    held = [(i + 1, Q) for i, Q in held]
                self._setup(chain, held)
                out.steps_added_at.append(iterations)
                systems, values, cval = self._evaluate(q)
                # Line 16: redo lines 2-13 with the new footstep.
                q = self._step(systems, q)
                iterations += 1
                systems, new_values, cval = self._evaluate(q)
                self._record(out, q, new_values)
                # the paper's test as written: every Delta V_i below its epsilon_i
                stalled = bool(np.all(values - new_values < self.epsilons))
                values = new_values
                if self._solved(values, cval):
                    reason = REASON_SOLVED
                    break
                if stalled:
                    # Lines 17-18: the extra footstep did not help: a local minimum (section 6.1).
                    reason = REASON_STALLED
                    break
                continue
            # Lines 2-4 (V^(0)) are the values at q; line 7: all tasks solved -> quit.
            if self._solved(values, cval):
                reason = REASON_SOLVED
                break
            if iterations >= self.request.max_iterations:
                reason = REASON_MAX_ITERATIONS
                break
            if self.budget.expired():
                reason = REASON_TIME_BUDGET
                break
            # Lines 5-6: solve the prioritized systems (7) and integrate.
            q = self._step(systems, q)
            iterations += 1
            systems, new_values, cval = self._evaluate(q)
            self._record(out, q, new_values)
            # Lines 10-14: value decrease of every task, eq. (15); all below epsilon -> add a step.
            grow = self._stalled(values, new_values) and not self._solved(new_values, cval)
            values = new_values
        if reason in (REASON_STALLED, REASON_MAX_STEPS) and not self.success(values, cval):
            # Algorithm 1 stops right after an iteration; let the chain settle (no more steps) so that
            # the equalities of level 0 and nearly met tasks converge.
            for _ in range(self.request.options.polish_iterations):
                if iterations >= self.request.max_iterations or self.budget.expired():
                    break
                q = self._step(systems, q)
                iterations += 1
                systems, new_values, new_cval = self._evaluate(q)
                self._record(out, q, new_values)
                progress = cval - new_cval > 1e-5 or bool(np.any(values - new_values > 1e-5))
                values, cval = new_values, new_cval
                if self.success(values, cval) or not progress:
                    break
        out.chain, out.q_tilde, out.values, out.constraint_value = self.chain, q, values, cval
        out.solved, out.reason, out.iterations = self.success(values, cval), reason, iterations
        return out


STEP_BOUND_INSET = (0.003, 0.005)  # [m], [rad]: see step_bounds


def step_bounds(
    robot: RobotModel, scale: float, inset: tuple[float, float] = STEP_BOUND_INSET
) -> FootstepBounds:
    """The relative step bounds the chain uses: the robot's, shrunk towards their middle by ``scale``
    (1: unchanged) and kept ``inset`` (m, rad) inside, so that the returned steps meet the robot's
    bounds exactly although the last step is met to first order and a discarded null step may have
    moved by up to the null-step tolerance (1 mm, 1 mrad)."""
    b = robot.params.footstep_bounds

    def shrink(lo: float, hi: float, pad: float) -> tuple[float, float]:
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * scale - pad
        return mid - half, mid + half

    dx = shrink(b.dx_min_m, b.dx_max_m, inset[0])
    dy = shrink(b.dy_min_m, b.dy_max_m, inset[0])
    dth = shrink(b.dtheta_min_rad, b.dtheta_max_rad, inset[1])
    return replace(
        b,
        dx_min_m=dx[0],
        dx_max_m=dx[1],
        dy_min_m=dy[0],
        dy_max_m=dy[1],
        dtheta_min_rad=dth[0],
        dtheta_max_rad=dth[1],
    )


def _preference(request: FootstepPlanRequest, out: _Outcome, alternative: tuple) -> tuple:
    """Section 5.2's order between solved start-foot choices: fewer steps, then the smaller posture
    residual. An objective (a task without tolerance, e.g. the rest posture) is never "solved", so
    the paper's rule does not apply to it as such; its value comes first, compared in units of its
    epsilon (a difference below epsilon is a tie), then the steps and the posture residual ("more
    sophisticated criteria may naturally be used instead", section 5.2)."""
    objectives = tuple(
        math.floor(v / t.eps())
        for t, v in zip(request.tasks, out.values, strict=True)
        if not math.isfinite(t.tol())
    )
    return (*objectives, alternative[2], alternative[3])


def _moved_footprints(out: _Outcome) -> bool:
    """Whether the outcome's plan has at least one step (a footprint off its initial pose)."""
    return bool(_footsteps(out.chain, out.q_tilde))


def _footsteps(chain: VirtualChain, q_tilde: np.ndarray) -> list[PlannedFootstep]:
    """Landings in walking order (F_1 .. F_{p-1}, then the front foot), null steps discarded: "the
    footprints that remained at their initial position and orientation are useless" (section 5.1)."""
    if chain.n_steps == 0:
        return []
    robot = chain.robot
    front = sole_pose_of(robot.sole_pose(chain.robot_q_world(q_tilde), chain.front_side, _robot_data(robot)))
    poses = [*chain.footprint_poses(q_tilde)[1:], front]
    sides = [*chain.sides[1:], chain.front_side]
    current = {"left": chain.start.left, "right": chain.start.right}
    steps: list[PlannedFootstep] = []
    for side, pose in zip(sides, poses, strict=True):
        if same_pose(pose, current[side]):
            continue
        current[side] = pose
        steps.append(PlannedFootstep(side, pose.x_m, pose.y_m, pose.yaw_rad))
    return steps


def _posture_residual(robot: RobotModel, request: FootstepPlanRequest, q_robot: np.ndarray) -> float:
    """||q_robot - q_rest|| over the actuated joints [rad] (section 5.2's tie-break)."""
    posture = next((t for t in request.tasks if t.kind == "posture"), None)
    return float(np.linalg.norm(q_robot[7:] - robot_rest(robot, posture)[7:]))


def plan_footsteps(request: FootstepPlanRequest, robot: RobotModel | None = None) -> FootstepPlanResult:
    """Plan the footsteps and the final whole-body configuration for ``request``.

    Raises:
        InvalidRequestError: malformed request (the message names the field).
        InfeasibleError: the tasks cannot be met (local minimum, step cap or iteration cap);
            ``details`` has ``residuals`` {task: value}, ``tolerances``, ``reason``, ``steps``,
            ``iterations`` and ``footsteps`` of the best attempt.
        RequestTimeoutError: the time budget ran out first (``reason`` "time_budget"), with the same
            ``details``: the best partial plan and its residuals.
    """
    result, error = plan_footsteps_best(request, robot)
    if error is not None:
        raise error
    return result


def plan_footsteps_best(
    request: FootstepPlanRequest, robot: RobotModel | None = None
) -> tuple[FootstepPlanResult, InfeasibleError | RequestTimeoutError | None]:
    """Like :func:`plan_footsteps`, but return the best attempt even when it fails, with the error
    that :func:`plan_footsteps` would raise (None on success): for figures of failures."""
    t0 = time.perf_counter()
    request.validate()
    robot = robot or load_robot(request.robot)
    if robot.name != request.robot:
        raise InvalidRequestError(
            f"robot model {robot.name!r} does not match request.robot {request.robot!r}"
        )
    q_start = (
        robot.check_q(np.asarray(request.q_start, dtype=float))
        if request.q_start is not None
        else np.array(robot.q_half_sitting)
    )
    posture = next((t for t in request.tasks if t.kind == "posture"), None)
    if posture is not None and posture.q_rest is not None:
        robot.check_q(np.asarray(posture.q_rest, dtype=float))
    stance = initial_stance(robot, q_start)
    budget = _Budget(request.time_budget_s)
    algo = _Algorithm1(request, budget)

    fronts: list[Side] = ["left", "right"] if request.front_foot == "auto" else [request.front_foot]  # type: ignore[list-item]
    outcomes: list[_Outcome] = []

    def cap() -> int | None:
        # Section 5.2 keeps the choice with fewer steps: once one choice is solved, another one
        # growing beyond its number of steps cannot be retained (unless an objective decides).
        done = [o.chain.n_steps for o in outcomes if o.solved]
        return min(done) if done and not algo.has_objective else None

    # Fig. 11: the structure starts with one step (the front foot free, held at its place at the
    # lowest priority), or with the initial guess of the number of steps (section 5.1).
    n0 = max(1, request.initial_steps)
    for front in fronts:
        if outcomes and outcomes[0].solved and not _moved_footprints(outcomes[0]):
            break  # solved without a step: the other start foot cannot need fewer
        chain = VirtualChain(robot, front, n0, stance, step_bounds(robot, request.options.step_region_scale))
        q = chain.folded_q(q_start)
        held = [(i, q[3 * (i - 1) : 3 * i].copy()) for i in range(1, chain.n_footprints)]
        outcomes.append(algo.run(chain, q, held=held, step_cap=cap()))

    results = [_result_of(robot, request, stance, out) for out in outcomes]
    alternatives = tuple(
        (out.front_side, out.solved, res.n_steps, _posture_residual(robot, request, np.array(res.q_final)))
        for out, res in zip(outcomes, results, strict=True)
    )
    elapsed = time.perf_counter() - t0
    solved = [i for i, alt in enumerate(alternatives) if alt[1]]
    if solved:
        # Section 5.2: fewer steps first, then the smaller posture residual.
        best_i = min(solved, key=lambda i: _preference(request, outcomes[i], alternatives[i]))
        return replace(results[best_i], solve_time_s=elapsed, alternatives=alternatives), None
    best_i = min(range(len(outcomes)), key=lambda i: tuple(outcomes[i].values / algo.tolerances))
    best = outcomes[best_i]
    residuals = {t.name: float(v) for t, v in zip(request.tasks, best.values, strict=True)}
    worst = max(zip(request.tasks, best.values, strict=True), key=lambda tv: tv[1] / tv[0].tol())
    # The budget cut the search short (of either start foot): nobody knows the tasks cannot be met, so
    # the answer is ``timeout`` with the best partial plan, not ``infeasible`` (issue 16).
    timed_out = any(o.reason == REASON_TIME_BUDGET for o in outcomes)
    error_type = RequestTimeoutError if timed_out else InfeasibleError
    verdict = "the time budget ran out before the tasks were met" if timed_out else "the tasks cannot be met"
    error = error_type(
        f"{verdict}: {worst[0].name} stays at {worst[1]:.4f} (tolerance {worst[0].tol():.4f}) "
        f"after {best.iterations} iterations and {best.chain.n_steps} steps ({_REASONS[best.reason]})",
        {
            "residuals": residuals,
            "tolerances": {t.name: t.tol() for t in request.tasks},
            "constraint_value": best.constraint_value,
            "reason": best.reason,
            "steps": best.chain.n_steps,
            "iterations": best.iterations,
            "solve_time_s": elapsed,
            "time_budget_s": request.time_budget_s,
            # the partial plan: the footsteps of the best attempt [side, x [m], y [m], yaw [rad]]
            "footsteps": [[f.side, f.x_m, f.y_m, f.yaw_rad] for f in results[best_i].footsteps],
        },
    )
    return replace(results[best_i], solve_time_s=elapsed, alternatives=alternatives), error


_REASONS = {
    REASON_STALLED: "no task improves even with an extra footstep: a local minimum of the gradient descent",
    REASON_MAX_STEPS: "the step cap max_steps was reached",
    REASON_MAX_ITERATIONS: "the iteration cap max_iterations was reached",
    REASON_TIME_BUDGET: "the time budget ran out",
    REASON_STEP_CAP: "the other start foot already needs fewer steps",
    REASON_SOLVED: "solved",
}


def _result_of(
    robot: RobotModel, request: FootstepPlanRequest, stance: Stance, out: _Outcome
) -> FootstepPlanResult:
    chain = out.chain
    steps = _footsteps(chain, out.q_tilde)
    residuals = tuple(
        TaskResidual(t.name, float(v), t.tol(), bool(v <= t.tol()))
        for t, v in zip(request.tasks, out.values, strict=True)
    )
    trace = None
    if request.record_trace:
        trace = PlanTrace(
            task_names=tuple(t.name for t in request.tasks),
            values=tuple(tuple(float(x) for x in v) for v in out.history_values),
            footprints=tuple(out.history_footprints),
            q_robot=tuple(tuple(float(x) for x in q) for q in out.history_q),
            steps_added_at=tuple(out.steps_added_at),
        )

    def triple(p: SolePose) -> tuple[float, float, float]:
        return (p.x_m, p.y_m, p.yaw_rad)

    return FootstepPlanResult(
        footsteps=tuple(steps),
        left_start=triple(stance.left),
        right_start=triple(stance.right),
        q_final=tuple(float(x) for x in chain.robot_q_world(out.q_tilde)),
        residuals=residuals,
        iterations=out.iterations,
        steps_added_at=tuple(out.steps_added_at),
        solve_time_s=0.0,
        front_foot=out.front_side,
        chain_steps=chain.n_steps,
        trace=trace,
    )


__all__ = ["initial_stance", "plan_footsteps", "plan_footsteps_best"]
