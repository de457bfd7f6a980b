"""The ``sim`` service: the pybullet world (sim/world.py) on the bus.

Run: ``python -m sim.service [--scene ball_fetch] [--seed 3] [--model talos] [--realtime]`` (plus the
common service options: ``--config``, ``--robot``, ``--hub``, ``--log-level``); the same options can
be given in the ``sim:`` section of the config file (:class:`sim.config.SimConfig`).

Time: physics only advances inside requests (execute, gripper, reset) by default, as fast as the CPU
allows, and stays frozen in between, so that runs are reproducible and idle services cost nothing.
With ``realtime`` the sim is paced at wall-clock speed and keeps stepping while idle (the robot stands,
the clock advances), like a real robot. ``joint_state``, ``base_pose`` and ``clock`` are published at
every 5 ms of sim time whenever physics runs, each only while someone subscribes (reading the state
costs ~12% of the execution's CPU, publishing the clock to nobody ~1.5%).

pybullet is not thread-safe: one lock serializes every access to the world (a render waits for a
running execute to finish).
"""

from __future__ import annotations

import argparse
import contextlib
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from services import budget
from services.bus.schemas import sim as msg
from services.bus.service import Service, config_with, handles, run_service
from services.errors import HumanoidError, InvalidRequestError, RequestTimeoutError
from services.model.options import add_model_argument, with_model
from sim.config import SimConfig
from sim.robot_info import kinematics_reply, robot_info_reply
from sim.scene import SceneSpec, find_scene, load_scene, parse_scene
from sim.world import World

_RESYNC_BEHIND_S = 0.1  # realtime pacing gives up catching up when this far behind the wall clock
#: Largest scene file ``sim/reset`` reads [bytes] (the shipped ones are 1-3 kB).
MAX_SCENE_BYTES = 256 * 1024
#: Longest motion ``sim/execute`` plays: samples x dt_s + hold_s [s of sim time].
MAX_EXECUTE_S = 120.0


class _OverBudgetError(Exception):
    """Raised from the tick hook when an execution passes its wall-clock budget."""


class SimService(Service):
    """Simulated robot and world (pybullet): executes trajectories, renders the head cameras, grasps."""

    name = "sim"
    Config = SimConfig

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--scene", help="scene at start-up (a name in sim/scenes or a YAML path)")
        parser.add_argument(
            "--scene-dir",
            action="append",
            default=[],
            help="a folder of more scenes <name>.yaml that sim/reset may load by name (repeatable)",
        )
        parser.add_argument(
            "--seed", type=int, help="seed of the start-up layout (default: the nominal layout)"
        )
        add_model_argument(parser)
        parser.add_argument(
            "--realtime", action="store_true", help="pace at wall-clock speed and step while idle"
        )

    @classmethod
    def configure(cls, config: SimConfig, args: argparse.Namespace) -> SimConfig:
        changes: dict[str, Any] = {k: v for k in ("scene", "seed") if (v := getattr(args, k)) is not None}
        if args.realtime:
            changes["realtime"] = True
        if args.scene_dir:
            changes["scene_dirs"] = (*config.scene_dirs, *args.scene_dir)
        config = with_model(config_with(config, **changes), args.model)
        _startup_scene(config)  # fail at start-up with a message rather than inside the running service
        return config

    def start(self) -> None:
        cfg: SimConfig = self.config
        self.lock = threading.RLock()
        self._deadline: float | None = None  # wall-clock end of the running execute's budget
        self.world = World(cfg.model, _startup_scene(cfg), cfg.seed, cfg)
        self._pub_state = self.publisher(msg.JOINT_STATE, track_matching=True)
        self._pub_base = self.publisher(msg.BASE_POSE, track_matching=True)
        self._pub_clock = self.publisher(msg.CLOCK, track_matching=True)
        self._pace_anchor: tuple[float, float] | None = None  # (sim time, wall time)
        self._pacing_in_tick = True
        self.world.on_tick = self._on_tick
        self._stop_idle = threading.Event()
        self._idle_thread: threading.Thread | None = None
        if cfg.realtime:
            self._idle_thread = threading.Thread(target=self._idle_loop, name="sim:idle", daemon=True)
            self._idle_thread.start()
        self.log.info(
            "world ready: robot %s, scene %s, %s",
            cfg.model,
            cfg.scene,
            "realtime" if cfg.realtime else "as fast as possible, frozen while idle",
        )

    def stop(self) -> None:
        self._stop_idle.set()
        if self._idle_thread is not None:
            self._idle_thread.join(timeout=1.0)
        with self.lock:
            self.world.on_tick = None
            self.world.close()

    # ------------------------------------------------------------------------------ publishing, pacing
    def _on_tick(self, world: World) -> None:
        t = world.sim_time_s
        if self._pub_state.matching or self._pub_base.matching:  # reading the state is ~80 us
            self._publish_state(world, t)
        if self._pub_clock.matching:  # a put costs even with nobody listening (~1.5% of an execution)
            self._pub_clock.put(msg.Clock(sim_time_s=t))
        if self._deadline is not None and time.monotonic() > self._deadline:
            self._deadline = None
            raise _OverBudgetError
        if self.config.realtime and self._pacing_in_tick:
            delay = self._pace_delay(t)
            if delay > 0.0:
                time.sleep(delay)

    def _publish_state(self, world: World, t: float) -> None:
        """``joint_state`` and ``base_pose`` at sim time ``t`` [s] (only while someone subscribes)."""
        state = world.state()
        xyzquat = pin.SE3ToXYZQUAT(world.base_pose())
        lin, ang = world.base_velocity()
        self._pub_state.put(msg.JointState(sim_time_s=t, q=state.q, v=state.v))
        self._pub_base.put(
            msg.BasePose(
                sim_time_s=t,
                position=xyzquat[:3].tolist(),
                quaternion=xyzquat[3:].tolist(),
                linear_velocity=lin.tolist(),
                angular_velocity=ang.tolist(),
            )
        )

    def _pace_delay(self, sim_time_s: float) -> float:
        """Wall time to wait so that sim time does not run ahead of the wall clock [s]."""
        now = time.monotonic()
        if self._pace_anchor is None:
            self._pace_anchor = (sim_time_s, now)
            return 0.0
        sim0, wall0 = self._pace_anchor
        ahead = (sim_time_s - sim0) - (now - wall0)
        if ahead < -_RESYNC_BEHIND_S:  # too slow to keep up: do not burst to catch up later
            self._pace_anchor = (sim_time_s, now)
            return 0.0
        return ahead

    def _idle_loop(self) -> None:
        while not self._stop_idle.is_set():
            with self.lock:
                self._pacing_in_tick = False
                try:
                    self.world.step_control()
                    delay = self._pace_delay(self.world.sim_time_s)
                finally:
                    self._pacing_in_tick = True
            if delay > 0.0:
                self._stop_idle.wait(delay)

    # ------------------------------------------------------------------------------ endpoints
    @handles(msg.STATE)
    def state(self, request: msg.StateRequest) -> msg.StateReply:
        with self.lock:
            w = self.world
            s = w.state()
            return msg.StateReply(
                sim_time_s=s.sim_time_s,
                model=w.robot.name,
                scene=w.layout.scene.name,
                seed=w.layout.seed,
                joint_names=list(w.robot.joint_names),
                q=s.q,
                v=s.v,
                held=dict(w.held),
                fallen=w.fallen(),
            )

    @handles(msg.ROBOT_INFO)
    def robot_info(self, request: msg.RobotInfoRequest) -> msg.RobotInfoReply:
        return robot_info_reply(self.world.robot)

    @handles(msg.KINEMATICS)
    def kinematics(self, request: msg.KinematicsRequest) -> msg.KinematicsReply:
        with budget.within_if(request.time_budget_s):
            return kinematics_reply(self.world.robot, request)

    @handles(msg.EXECUTE)
    def execute(self, request: msg.ExecuteRequest) -> msg.ExecuteReply:
        q = np.asarray(request.q, dtype=float)
        length_s = len(q) * request.dt_s + request.hold_s
        if length_s > MAX_EXECUTE_S:
            raise InvalidRequestError(
                f"the motion lasts {length_s:.1f} s ({len(q)} samples x dt_s {request.dt_s} s + hold_s "
                f"{request.hold_s} s): at most {MAX_EXECUTE_S:.0f} s in one sim/execute; split it",
                {"field": "q", "limit_s": MAX_EXECUTE_S},
            )
        with self.lock:
            started = time.monotonic()
            budget = self.config.execute_budget_s if request.time_budget_s is None else request.time_budget_s
            self._deadline = started + budget
            t0 = self.world.sim_time_s
            try:
                r = self.world.execute(
                    q,
                    request.dt_s,
                    tuple(request.allowed_contacts),
                    request.stop_on_collision,
                    request.hold_s,
                    tuple(request.leaving),
                    tuple(request.supports),
                    dict(request.effort_scale),
                )
            except _OverBudgetError:
                played = self.world.sim_time_s - t0
                raise RequestTimeoutError(
                    f"sim/execute stopped after its time budget of {budget} s: {played:.3f} s of the "
                    f"{length_s:.3f} s motion played; the robot holds its last command",
                    {"played_s": played, "duration_s": length_s},
                ) from None
            finally:
                self._deadline = None
        return msg.ExecuteReply(
            outcome=r.outcome,
            message=r.message,
            sim_time_s=r.state.sim_time_s,
            duration_s=r.duration_s,
            samples_executed=r.samples_executed,
            q=r.state.q,
            v=r.state.v,
            tracking_error_rad=r.tracking_error_rad,
            tracking_rms_rad=r.tracking_rms_rad,
            worst_joint=r.worst_joint,
            base_error_m=r.base_error_m,
            foot_slip_m=r.foot_slip_m,
            collisions=[
                msg.Contact(
                    robot_link=c.robot_link,
                    other=c.other,
                    position=[float(x) for x in c.position],
                    normal_force_n=float(c.normal_force_n),
                )
                for c in r.collisions
            ],
            fall_base_height_m=r.fall_base_height_m,
            fall_tilt_rad=r.fall_tilt_rad,
        )

    @handles(msg.RENDER)
    def render(self, request: msg.RenderRequest) -> msg.RenderReply:
        """The images of a camera or stereo pair; with ``time_budget_s``, the wait for the world and
        every draw are bounded by it (a draw that would end past it is not started: ``timeout``)."""
        with budget.within_if(request.time_budget_s):
            return self._render(request)

    @contextlib.contextmanager
    def _locked(self, where: str) -> Iterator[None]:
        """The world's lock, waited for at most what is left of the request's budget (RequestTimeoutError
        naming ``where`` past it), or as long as it takes when no budget is open."""
        deadline = budget.current()
        if deadline is None:
            with self.lock:
                yield
            return
        while not self.lock.acquire(timeout=max(deadline.remaining(), 0.0)):
            budget.check(where)
        try:
            yield
        finally:
            self.lock.release()

    def _render(self, request: msg.RenderRequest) -> msg.RenderReply:
        with self._locked("the wait for the world (the sim busy with another request)"):
            w = self.world
            images = w.render(
                request.camera,
                request.width_px,
                request.height_px,
                depth=request.depth,
                segmentation=request.segmentation,
            )
            t = w.sim_time_s
            pair = w.robot.stereo_pairs.get(request.camera)
        return msg.RenderReply(
            sim_time_s=t,
            baseline_m=pair.baseline_m if pair is not None else 0.0,
            images=[
                msg.CameraImage(
                    name=im.name,
                    width_px=im.intrinsics.width_px,
                    height_px=im.intrinsics.height_px,
                    K=im.intrinsics.K,
                    T_world_camera=im.T_world_camera,
                    rgb=im.rgb,
                    depth_m=im.depth_m,
                    segmentation=im.segmentation,
                    labels=dict(im.labels),
                )
                for im in images
            ],
        )

    @handles(msg.GRIPPER)
    def gripper(self, request: msg.GripperRequest) -> msg.GripperReply:
        with self.lock:
            r = self.world.gripper(request.side, request.action)
        return msg.GripperReply(
            side=r.side,
            action=r.action,
            outcome=r.outcome,
            held=r.held,
            released=r.released,
            finger_q=r.finger_q,
            sim_time_s=r.sim_time_s,
        )

    @handles(msg.RESET)
    def reset(self, request: msg.ResetRequest) -> msg.ResetReply:
        scene = self._named_scene(request.scene) if request.scene else None
        with self.lock:
            w = self.world
            layout = w.reset(scene, request.seed)
            self._pace_anchor = None
            return msg.ResetReply(
                scene=layout.scene.name,
                seed=layout.seed,
                objects=[o.name for o in layout.objects],
                q=w.state().q,
                sim_time_s=w.sim_time_s,
            )

    def _named_scene(self, name: str) -> SceneSpec:
        """The scene ``name`` from the scene folders (the request's schema allows names only, never a
        path); a broken file is logged here and reported without its content."""
        path = find_scene(name, self.config.scene_dirs)
        if path.stat().st_size > MAX_SCENE_BYTES:
            raise InvalidRequestError(f"scene {name!r} is larger than {MAX_SCENE_BYTES} bytes")
        try:
            return parse_scene(yaml.safe_load(path.read_bytes()), source=name)
        except (HumanoidError, yaml.YAMLError, RecursionError, ValueError, TypeError) as exc:
            self.log.warning("scene %s (%s) does not load: %s", name, path, exc)
            raise InvalidRequestError(
                f"scene {name!r} is not a valid scene file (the sim's log says why)", {"field": "scene"}
            ) from None

    @handles(msg.GROUND_TRUTH)
    def ground_truth(self, request: msg.GroundTruthRequest) -> msg.GroundTruthReply:
        with self.lock:
            w = self.world
            objects = w.ground_truth()
            xyzquat = pin.SE3ToXYZQUAT(w.base_pose())
            return msg.GroundTruthReply(
                sim_time_s=w.sim_time_s,
                scene=w.layout.scene.name,
                seed=w.layout.seed,
                base_position=xyzquat[:3].tolist(),
                base_quaternion=xyzquat[3:].tolist(),
                objects=[
                    msg.ObjectState(
                        name=o.name,
                        kind=o.kind,
                        position=o.position.tolist(),
                        quaternion=o.quaternion.tolist(),
                        colour=list(o.colour),
                        size_m=list(o.size_m),
                        radius_m=o.radius_m,
                        length_m=o.length_m,
                        mass_kg=o.mass_kg,
                        held_by=o.held_by,
                    )
                    for o in objects.values()
                ],
            )

    @handles(msg.SNAPSHOT)
    def snapshot(self, request: msg.SnapshotRequest) -> msg.SnapshotReply:
        """A PNG from an external viewpoint; ``time_budget_s`` bounds it as :meth:`render`'s."""
        with budget.within_if(request.time_budget_s):
            return self._snapshot(request)

    def _snapshot(self, request: msg.SnapshotRequest) -> msg.SnapshotReply:
        eye = tuple(request.eye) if request.eye is not None else None
        target = tuple(request.target) if request.target is not None else None
        for name, value in (("eye", eye), ("target", target)):
            if value is not None and len(value) != 3:
                raise InvalidRequestError(f"snapshot {name} must be [x, y, z] in metres, got {list(value)}")
        with self._locked("the wait for the world (the sim busy with another request)"):
            png = self.world.snapshot(request.viewpoint, request.width_px, request.height_px, eye, target)
            t = self.world.sim_time_s
        return msg.SnapshotReply(sim_time_s=t, png=np.frombuffer(png, dtype=np.uint8))


def _startup_scene(config: SimConfig) -> SceneSpec:
    """The start-up scene: a YAML path, or a name looked up in the scene folders (shipped first)."""
    if config.scene.endswith((".yaml", ".yml")):
        return load_scene(config.scene)
    return load_scene(find_scene(config.scene, config.scene_dirs))


if __name__ == "__main__":
    raise SystemExit(run_service(SimService))
