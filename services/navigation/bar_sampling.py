"""Random collision-free configurations of the carried bar near a collision, checked by IK.

"When a collision is found, a new random collision-free configuration near the colliding one is first
generated, and then an IK solver is applied to ensure the geometric constraints of the end-effector"
(section "Smooth Motion Reshaping" of `001_771c0ce3779b0683.txt`). :class:`BarPoseSampler` draws
offsets of the bar's pose (:class:`~services.navigation.reshaping.BarOffset`: forward, left, up, roll,
yaw, within the arms' reach given by :class:`~services.navigation.reshaping.SamplingOptions`) in boxes
of growing size around the colliding configuration, keeps those whose whole reshaped task-space motion
(anticipating to regaining, the quintic ramps included) clears every obstacle, and among them returns
the nearest one the arms reach (:class:`ArmReach`: an IK on the arm joints at the collision's
configurations, the body as the walk has it).

Frames: world z-up; bar poses as in :mod:`services.navigation.carry` (centre [m], unit axis).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from services.collision.carried import BarGrip
from services.collision.motion import MotionChecker
from services.collision.obstacles import Scene, obstacle_geometry
from services.ik import Level
from services.ik.dofs import dof_mask
from services.ik.solver import HierarchicalSolver
from services.navigation.carry import BarTrajectory, bar_rotation, hands_on_bar
from services.navigation.reshaping import (
    BarOffset,
    ReshapeOptions,
    ReshapeWindow,
    apply_offsets,
    make_window,
)

_R_CAPSULE_Z_TO_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # capsule axis z -> x


@dataclass(frozen=True)
class SampleStats:
    """What one sampling did: candidates drawn, rejected because the bar, a hand (or, after the reach
    check, an arm) comes too close to
    an obstacle, rejected because the arms do not reach them, and the ring (1-based) of the result."""

    drawn: int
    collide: int
    unreachable: int
    ring: int


class ArmReach:
    """The arms-only IK of the sampled bar pose ("an IK solver is applied to ensure the geometric
    constraints of the end-effector"): both hands on the bar (:class:`HandOnBarTask`), only the arm
    joints move, the rest of the body as in the walk's configuration.

    ``model`` is the IK model (the walking planner's, grippers locked); ``reduce`` maps a full
    configuration to it, ``expand(q_reduced, q_full)`` back (the locked joints from ``q_full``).
    """

    def __init__(
        self,
        robot: object,
        model: pin.Model,
        grip: BarGrip,
        reduce: object,
        expand: object,
        iterations: int,
    ) -> None:
        self.model = model
        self.reduce = reduce
        self.expand = expand
        self.grip = grip
        self.iterations = iterations
        self.solver = HierarchicalSolver(model)
        self.tasks = hands_on_bar(model, grip)
        arms = robot.arm_joints("left") + robot.arm_joints("right")  # type: ignore[attr-defined]
        self.level = Level(tuple(self.tasks.values()), name="hands_on_bar", selection=dof_mask(model, arms))
        joints = [model.joints[model.getJointId(name)] for name in arms]
        self.arm_q = np.array([j.idx_q for j in joints], dtype=int)
        self.v_max = np.array([model.velocityLimit[j.idx_v] for j in joints])

    def track(
        self, qs: np.ndarray, ks: np.ndarray, centre_m: np.ndarray, axis: np.ndarray, dt_s: float
    ) -> tuple[float, float, np.ndarray]:
        """Follow the bar poses (centre (m, 3) [m], axis (m, 3)) at samples ``ks`` (m,) of the motion
        ``qs`` (n, nq) with the arms only, from the arms of ``qs[ks[0]]`` (the body as ``qs`` has it),
        ``iterations`` Gauss-Newton steps per sample, as the walk's whole-body IK tracks its knots.

        Returns the largest hand error [m] (held point, or axis misalignment times the bar's half
        length), the largest arm joint speed as a fraction of its limit (``dt_s`` [s] per sample) and
        the configurations reached (m, nq) (full model)."""
        q_arms = self.reduce(qs[ks[0]])[self.arm_q]  # type: ignore[operator]
        worst_error = worst_speed = 0.0
        half = 0.5 * self.grip.bar.length_m
        data = self.model.createData()
        k_prev = int(ks[0])
        reached = np.empty((len(ks), qs.shape[1]))
        for i, k in enumerate(ks):
            q = self.reduce(qs[k])  # type: ignore[operator]
            q[self.arm_q] = q_arms
            for side, task in self.tasks.items():
                task.set_target(centre_m[i] + self.grip.along_m[side] * axis[i], axis[i])
            for _ in range(self.iterations):
                q = pin.integrate(self.model, q, self.solver.solve([self.level], q))
            if k > k_prev:
                speed = np.abs(q[self.arm_q] - q_arms) / ((k - k_prev) * dt_s) / self.v_max
                worst_speed = max(worst_speed, float(speed.max()))
            q_arms, k_prev = q[self.arm_q].copy(), int(k)
            reached[i] = self.expand(q, qs[k])  # type: ignore[operator]
            pin.forwardKinematics(self.model, data, q)
            pin.updateFramePlacements(self.model, data)
            for task in self.tasks.values():
                e = task.compute_error(q, data)
                worst_error = max(
                    worst_error, float(np.linalg.norm(e[:3])), half * float(np.linalg.norm(e[3:]))
                )
        return worst_error, worst_speed, reached


class BarPoseSampler:
    """Random collision-free bar offsets near a collision (see the module doc).

    ``scene``: the obstacles; ``grip``: the bar held; ``options``: the reshaping options (clearances,
    ramp bounds, :class:`~services.navigation.reshaping.SamplingOptions`); ``reach``: the IK check;
    ``rng``: the seeded generator (the same request gives the same samples); ``checker``: the 3D check of
    the robot (when given, the arms of the configurations the reach check reaches must keep the
    required clearance to every obstacle).
    """

    def __init__(
        self,
        scene: Scene,
        grip: BarGrip,
        options: ReshapeOptions,
        reach: ArmReach,
        rng: np.random.Generator,
        checker: MotionChecker | None = None,
    ) -> None:
        self.grip = grip
        self.options = options
        self.reach = reach
        self.rng = rng
        self.checker = checker
        self.obstacles = [(o, *obstacle_geometry(o)) for o in scene.obstacles]
        self.bar_shape = coal.Capsule(grip.bar.radius_m, grip.bar.length_m)
        self.hand_shape = coal.Sphere(options.sampling.hand_radius_m)
        self._request = coal.DistanceRequest()
        self._result = coal.DistanceResult()
        self.half_length_m = 0.5 * grip.bar.length_m

    # ------------------------------------------------------------------------------ distances
    def _distance(self, shape: coal.CollisionGeometry, T: coal.Transform3s, j: int) -> float:
        _, o_shape, T_o, _ = self.obstacles[j]
        self._result.clear()
        return float(coal.distance(shape, T, o_shape, T_o, self._request, self._result))

    def clearance_m(self, centre_m: np.ndarray, axis: np.ndarray, obstacles: list[int]) -> float:
        """Smallest signed distance [m] of the bar (capsule) and of the hand spheres at the held points,
        posed at ``centre_m`` / ``axis``, to the obstacles indexed ``obstacles``."""
        R = bar_rotation(axis) @ _R_CAPSULE_Z_TO_X
        T_bar = coal.Transform3s(R, np.asarray(centre_m, dtype=float))
        best = math.inf
        hands = [
            coal.Transform3s(np.eye(3), centre_m + self.grip.along_m[side] * axis)
            for side in ("left", "right")
        ]
        for j in obstacles:
            best = min(best, self._distance(self.bar_shape, T_bar, j))
            for T in hands:
                best = min(best, self._distance(self.hand_shape, T, j))
        return best

    def _near_obstacles(self, centre_m: np.ndarray, exempt: set[int]) -> list[int]:
        """Obstacles whose floor disc comes within the bar's reach + the largest sampled move of a
        sample of ``centre_m`` (k, 3), except ``exempt``."""
        s = self.options.sampling
        reach = self.half_length_m + self.grip.bar.radius_m + s.hand_radius_m + s.max_forward_m + s.max_left_m
        out = []
        for j, (o, _, _, radius) in enumerate(self.obstacles):
            if j in exempt:
                continue
            gap = np.hypot(centre_m[:, 0] - o.center_xyz_m[0], centre_m[:, 1] - o.center_xyz_m[1])
            if (gap < reach + radius + self.options.target_clearance_m).any():
                out.append(j)
        return out

    def initial_contacts(self, nominal: BarTrajectory) -> set[int]:
        """Obstacles the bar touches at the motion's first sample (its stands): not collisions (as the
        3D check's release rule)."""
        near = self._near_obstacles(nominal.centre_m[:1], set())
        return {
            j
            for j in near
            if self.clearance_m(nominal.centre_m[0], nominal.axis[0], [j]) < self.options.required_clearance_m
        }

    def _arms_clear(self, qs: np.ndarray, dt_s: float) -> bool:
        """The arms along ``qs`` (m, nq) keep the required clearance to every obstacle."""
        if self.checker is None:
            return True
        check = self.checker.check(qs, dt_s, release_m=0.0)
        return bool(check.min_distance("arms").min() >= self.options.required_clearance_m)

    # ------------------------------------------------------------------------------- sampling
    def free(
        self,
        window: ReshapeWindow,
        nominal: BarTrajectory,
        others: list[ReshapeWindow],
        hold: np.ndarray,
        exempt: set[int],
    ) -> bool:
        """The reshaped task-space motion over ``window`` (the other windows ``others`` applied too)
        keeps the target clearance to every obstacle (checked every ``check_every`` samples, the hold's
        samples ``hold`` first), and the bar's centre under ``max_bar_height_m``."""
        t = nominal.times_s
        k0 = int(np.searchsorted(t, window.t_anticipate_s))
        k1 = int(np.searchsorted(t, window.t_regain_s, side="right"))
        ks = np.unique(np.concatenate([hold, np.arange(k0, k1, self.options.sampling.check_every), [k1 - 1]]))
        order = np.concatenate([hold, np.setdiff1d(ks, hold)])
        order = order[(order >= 0) & (order < t.shape[0])]
        offsets = window.weight(t[order])[:, None] * window.offset.as_array()[None, :]
        for w in others:
            offsets += w.weight(t[order])[:, None] * w.offset.as_array()[None, :]
        centre, axis = apply_offsets(nominal.centre_m[order], nominal.axis[order], offsets)
        limit = self.options.max_bar_height_m
        if limit is not None and centre[:, 2].max() > limit:
            return False
        near = self._near_obstacles(centre, exempt)
        clearance = self.options.target_clearance_m
        return all(self.clearance_m(centre[i], axis[i], near) >= clearance for i in range(centre.shape[0]))

    def sample(
        self,
        t_collide_s: float,
        t_collide_end_s: float,
        obstacles: tuple[str, ...],
        base: BarOffset,
        nominal: BarTrajectory,
        qs: np.ndarray,
        others: list[ReshapeWindow],
        exempt: set[int],
        rejected: list[ReshapeWindow] | None = None,
    ) -> tuple[ReshapeWindow | None, SampleStats]:
        """The window holding, over [t_collide_s, t_collide_end_s] [s], an offset drawn around ``base``
        (the colliding configuration: zero, or the offset of the window being reshaped again): among the
        collision-free ones of the first ring holding any, the nearest to the nominal pose that the arms
        reach (the next nearest when not, ``max_ik_checks`` at most); None when no drawn candidate is
        both. ``qs`` (n, nq): the
        whole-body motion being reshaped (its configurations at the hold are where the arms' reach is
        checked); ``others``: the windows kept as they are; ``rejected``: windows the whole-body IK could
        not follow: candidates within ``reject_radius`` of their offsets (in units of the bounds' half
        ranges) are not drawn."""
        s = self.options.sampling
        t = nominal.times_s
        t_first, t_last = float(t[0]), float(t[-1])
        k_c0 = int(np.searchsorted(t, t_collide_s))
        k_c1 = min(int(np.searchsorted(t, t_collide_end_s, side="right")) - 1, t.shape[0] - 1)
        k_c1 = max(k_c1, k_c0)
        hold = np.unique(np.linspace(k_c0, k_c1, max(2, (k_c1 - k_c0) // s.check_every + 1)).astype(int))
        lower, upper = s.lower, s.upper
        scale = np.maximum(upper - lower, 1e-9)
        drawn = collide = unreachable = ik_checks = 0
        b = base.as_array()
        for ring in range(1, s.rings + 1):
            r = ring / s.rings
            cand = b + r * (lower + self.rng.random((s.samples_per_ring, 5)) * (upper - lower))
            cand = np.clip(cand, lower, upper)
            drawn += cand.shape[0]
            norms = np.linalg.norm(2.0 * cand / scale, axis=1)  # distance from the nominal pose
            for w in rejected or []:
                near = np.linalg.norm(2.0 * (cand - w.offset.as_array()) / scale, axis=1) < s.reject_radius
                cand, norms = cand[~near], norms[~near]
            free: list[tuple[float, ReshapeWindow]] = []
            for c, norm in zip(cand, norms, strict=True):
                offset = BarOffset.from_array(c)
                window = make_window(
                    t_collide_s,
                    t_collide_end_s,
                    offset,
                    obstacles,
                    self.options,
                    t_first,
                    t_last,
                    self.half_length_m,
                    float(nominal.centre_m[k_c0, 2]),
                )
                if self.free(window, nominal, others, hold, exempt):
                    free.append((float(norm), window))
                else:
                    collide += 1
            for _, window in sorted(free, key=lambda item: item[0]):
                if ik_checks >= s.max_ik_checks:
                    break
                ik_checks += 1
                k0 = int(np.searchsorted(t, window.t_anticipate_s))
                k1 = min(int(np.searchsorted(t, window.t_regain_s, side="right")), t.shape[0] - 1)
                ks = np.unique(np.append(np.arange(k0, k1, s.track_every), k1))
                offsets = window.weight(t[ks])[:, None] * window.offset.as_array()[None, :]
                for w in others:
                    offsets += w.weight(t[ks])[:, None] * w.offset.as_array()[None, :]
                centre, axis = apply_offsets(nominal.centre_m[ks], nominal.axis[ks], offsets)
                dt = float(t[1] - t[0])
                error, speed, reached = self.reach.track(qs, ks, centre, axis, dt)
                if error <= 0.5 * self.options.max_hand_error_m and speed <= s.max_speed_ratio:
                    if self._arms_clear(reached, dt):
                        return window, SampleStats(drawn, collide, unreachable, ring)
                    collide += 1
                    continue
                unreachable += 1
            if ik_checks >= s.max_ik_checks:
                break
        return None, SampleStats(drawn, collide, unreachable, 0)


__all__ = ["ArmReach", "BarPoseSampler", "SampleStats"]
