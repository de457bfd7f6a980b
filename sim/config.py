"""Configuration of the simulation (one frozen dataclass; YAML section ``sim:`` overrides the defaults)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from services.errors import InvalidRequestError


@dataclass(frozen=True)
class SimConfig:
    """Options of the sim world and service.

    Attributes:
        model: robot model name (``services.model.load_robot``): ``hrp2_like`` or ``talos``.
        scene: scene loaded at start-up (a name in the scene folders or a YAML path: the operator's
            choice; ``sim/reset`` requests name scenes only, never a path).
        scene_dirs: more folders of scene files ``<name>.yaml`` that ``sim/reset`` may load by name,
            searched after the shipped ``sim/scenes`` (a request never names a path).
        seed: seed of the start-up layout (None: the nominal layout of the scene file).
        realtime: pace the simulation at wall-clock speed and keep stepping while idle (robot standing);
            off (default): execute as fast as possible and freeze physics between requests.
        physics_dt_s: physics step [s] (1 kHz).
        control_dt_s: trajectory sample period and state publishing period [s] (5 ms = 200 Hz).
        solver_iterations: pybullet constraint solver iterations per step (None: the robot's
            ``pybullet_solver_iterations``, 20 for hrp2_like, 50 for talos).
        position_gain, velocity_gain: pybullet position-control gains of every joint (the motor is a
            constraint: ``kp (q* - q) / dt + kd (v* - v)``, forces capped at the URDF effort limits).
        execute_budget_s: wall-clock budget of a ``sim/execute`` that gives none [s]: past it the
            robot holds where it is and the reply is ``timeout`` (no request holds the sim longer).
        max_start_jump_rad: a trajectory whose first sample is farther than this from the current
            joint positions is rejected (plan from the current state, ``sim/state``) [rad].
        gripper_timeout_s: longest opening/closing motion of a gripper [s].
        settle_s: physics time run after a reset so that objects come to rest [s].
        loaded_foot_force_n: a sole carries weight (and its slip is measured) above this normal force [N].
        contact_force_n: contacts weaker than this are ignored when looking for collisions [N].
        start_contact_push_m: a contact the robot is in when a motion starts stays allowed while the
            planned motion moves its contact points no more than this further into the object [m]
            (:mod:`sim.start_contacts`).
        render_near_m, render_far_m: clipping planes of the cameras [m].
        stabilizer: leg corrections from the measured body inclination during executions
            (:mod:`sim.stabilizer`, as the real robot's stabilizer); off (the default: with it on fetch
            seed 6 failed, sim/README.md): the trajectories are played open loop.
        stabilizer_gain: correction per radian of inclination error [rad/rad].
        stabilizer_damping_s: correction per rad/s of inclination rate error [s].
        stabilizer_max_rad: largest correction [rad].
        stabilizer_loaded_n: the stabilizer corrects only while the two soles' floor forces add up to
            this [N] (both soles together: ``loaded_foot_force_n`` is per sole).
        stabilizer_contact_n: the stabilizer holds its correction while contacts other than the soles
            on the floor and the hands on what they hold push on the robot with this much in total [N],
            and for 0.1 s after (a hand on a box, a shank on a table: a tilt they hold is not the
            feet's to correct).
    """

    model: str = "hrp2_like"
    scene: str = "empty"
    scene_dirs: tuple[str, ...] = ()
    seed: int | None = None
    realtime: bool = False
    physics_dt_s: float = 0.001
    control_dt_s: float = 0.005
    solver_iterations: int | None = None
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    max_start_jump_rad: float = 0.2
    execute_budget_s: float = 300.0
    gripper_timeout_s: float = 2.5
    settle_s: float = 0.3
    loaded_foot_force_n: float = 30.0
    contact_force_n: float = 0.05
    start_contact_push_m: float = 0.003
    render_near_m: float = 0.05
    render_far_m: float = 30.0
    stabilizer: bool = False
    stabilizer_gain: float = 1.0
    stabilizer_damping_s: float = 0.02
    stabilizer_max_rad: float = 0.05
    stabilizer_loaded_n: float = 30.0
    stabilizer_contact_n: float = 5.0

    def __post_init__(self) -> None:
        for name in (
            "physics_dt_s",
            "control_dt_s",
            "position_gain",
            "velocity_gain",
            "max_start_jump_rad",
            "execute_budget_s",
            "gripper_timeout_s",
            "render_near_m",
            "render_far_m",
            "start_contact_push_m",
        ):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InvalidRequestError(f"sim config: {name} must be a positive number, got {value!r}")
        for name in (
            "stabilizer_gain",
            "stabilizer_damping_s",
            "stabilizer_max_rad",
            "stabilizer_loaded_n",
            "stabilizer_contact_n",
        ):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise InvalidRequestError(f"sim config: {name} must be a number >= 0, got {value!r}")
        if self.settle_s < 0 or self.contact_force_n < 0 or self.loaded_foot_force_n < 0:
            raise InvalidRequestError(
                "sim config: settle_s, contact_force_n and loaded_foot_force_n must be >= 0"
            )
        if self.solver_iterations is not None and (
            isinstance(self.solver_iterations, bool)
            or not isinstance(self.solver_iterations, int)
            or self.solver_iterations < 1
        ):
            raise InvalidRequestError(
                "sim config: solver_iterations must be an integer >= 1 (or null: the robot's), "
                f"got {self.solver_iterations!r}"
            )
        ratio = self.control_dt_s / self.physics_dt_s
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise InvalidRequestError(
                f"sim config: control_dt_s ({self.control_dt_s}) must be a multiple of physics_dt_s "
                f"({self.physics_dt_s})"
            )
        if self.render_near_m >= self.render_far_m:
            raise InvalidRequestError("sim config: render_near_m must be below render_far_m")

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return round(self.control_dt_s / self.physics_dt_s)
