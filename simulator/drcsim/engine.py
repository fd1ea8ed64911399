"""One simulation run: world, robot control, behaviours, sensors, scoring and logs at 1 kHz."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drcsim import __version__
from drcsim._bullet import new_client
from drcsim.behaviours import Behaviours
from drcsim.briefing import rough_briefing
from drcsim.control import JointController
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.estimator import Estimator
from drcsim.mcaplog import log_path
from drcsim.mcaprun import RunRecorder
from drcsim.mud import MudDrag
from drcsim.runlog import RunLog, state_digest
from drcsim.scene import TICK_STEPS, TIMESTEP, build_scene
from drcsim.scoring import GateFrame, Observation, Scorer
from drcsim.sensors import Sensors, SensorSettings
from drcsim.viewer import PoseStream, scene_roles
from drcsim.worlds import load_world

Publisher = Callable[[str, dict[str, Any]], None]


@dataclass
class RunOptions:
    """How to run a world: logs, time limit, sensors and where messages go."""

    log_dir: Path | None = None
    world_document: dict[str, Any] | None = None  # None: the shipped copy
    time_limit_s: float | None = None
    sensors: SensorSettings = field(default_factory=SensorSettings)
    publish: Publisher | None = None
    pose_rate_hz: float = 30.0  # frames of the on-demand `poses` topic, in simulated time
    mcap_pose_hz: float = 100.0  # body poses (/tf) in the run's MCAP log, in simulated time
    wall_clock: Callable[[], float] = time.time


class Simulation:
    """A world in one run configuration, stepped at 1 kHz; deterministic for given commands."""

    def __init__(self, world: str, config: str | int, options: RunOptions | None = None):
        self.options = options or RunOptions()
        self.spec = load_world(
            world, config, self.options.time_limit_s, self.options.world_document
        )
        self.client = new_client()
        self.scene = build_scene(self.client, self.spec)
        self.controller = JointController(
            self.client, self.scene.robot, self.scene.robot_joints, TIMESTEP
        )
        self.mud = MudDrag(self.client, self.scene.robot, self.scene.mud, TIMESTEP)
        self.drive = (
            VehicleDrive(self.client, self.scene.vehicle, self.scene.vehicle_joints)
            if self.scene.vehicle is not None
            else None
        )
        self.behaviours = Behaviours(self.scene, self.controller, self.drive, self.spec.assists)
        self.briefing = rough_briefing(self.scene.course, self.spec)
        self.estimator = Estimator(self.client, self.scene.robot, self.controller, self.spec.seed)
        self.sensors = Sensors(
            self.scene, self.controller, self.options.sensors, self.spec.seed, TIMESTEP
        )
        gates = {name: GateFrame(g.x, g.y, g.yaw, g.width) for name, g in self.scene.gates.items()}
        self.scorer = Scorer(self.spec.checkpoints, gates, self.spec.time_limit_s)
        self.step_count = 0
        self.active_topics: set[str] = set()
        self.poses = PoseStream(self.client, self.options.pose_rate_hz)
        self.pose_every = self.poses.every_steps(TIMESTEP)
        self.hose_start_z = self._hose_z()
        self.log: RunLog | None = None
        self.recorder: RunRecorder | None = None
        if self.options.log_dir is not None:
            self.log = RunLog(self.options.log_dir, self.meta(), self.options.world_document)
            every = max(1, round(100.0 / self.options.mcap_pose_hz))  # ticks are 100 Hz
            self.recorder = RunRecorder(
                log_path(self.options.log_dir), self.client, scene_roles(self), self.meta(), every
            )
        self.closed = False
        self._emit_score([{"event": "run_start", "sim_time": 0.0, "score": 0}])

    # -- description ----------------------------------------------------------------------
    def meta(self) -> dict[str, Any]:
        """Return what a replay needs to rebuild this run."""
        return {
            "world": self.spec.name,
            "config": self.spec.config,
            "seed": self.spec.seed,
            "world_digest": self.spec.digest,
            "time_limit_s": self.spec.time_limit_s,
            "timestep": TIMESTEP,
            "drcsim_version": __version__,
        }

    @property
    def sim_time(self) -> float:
        """Return the simulated time in seconds."""
        return self.step_count * TIMESTEP

    @property
    def ended(self) -> bool:
        """Return whether the run is over."""
        return self.scorer.ended

    # -- commands -------------------------------------------------------------------------
    def apply_command(self, message: dict[str, Any], source: str = "") -> dict[str, Any]:
        """Apply a checked command (see protocol.check_command) before the next step;
        `source` is the sender's address, for the record."""
        if self.ended:
            return {"ok": False, "error": "the run has ended"}
        if self.log is not None:
            self.log.command(self.step_count, message)
        if self.recorder is not None:
            self.recorder.command(self.sim_time, self.step_count, message, source)
        try:
            details = self._dispatch(message)
        except CommandError as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": True, **details}

    def _dispatch(self, message: dict[str, Any]) -> dict[str, Any]:
        op = message["op"]
        if op == "joints":
            named = [n for key in ("gains", "position", "torque") for n in message.get(key, {})]
            self.behaviours.check_free(named)  # all or nothing: a refused command changes nothing
            for name, (kp, ki, kd) in message.get("gains", {}).items():
                self.controller.set_gains(name, kp, ki, kd)
            for name, value in message.get("position", {}).items():
                self.controller.set_position(name, value)
            for name, value in message.get("torque", {}).items():
                self.controller.set_torque(name, value)
            return {}
        if op == "behaviour":
            params = {k: v for k, v in message.items() if k not in ("op", "id", "name")}
            return self.behaviours.command(message["name"], params, fallen=self.scorer.down)
        if op == "stop":
            self._emit_score(self.scorer.stop(self.sim_time, "stopped"))
            self._finish()
            return {}
        raise CommandError(f"op {op!r} is not a simulation command")

    # -- stepping -------------------------------------------------------------------------
    def step(self, count: int = 1) -> int:
        """Advance up to `count` physics steps (fewer if the run ends); return how many ran."""
        done = 0
        while done < count and not self.ended:
            self.behaviours.apply()
            self.controller.apply()
            self.mud.apply(self.step_count)
            self.client.stepSimulation()
            self.step_count += 1
            done += 1
            if self.step_count % TICK_STEPS == 0:
                self._tick()
            publish = self.options.publish
            if publish is not None and self.active_topics:
                for topic in self.sensors.due(self.step_count, self.active_topics):
                    message = self.sensors.compute(topic, self.sim_time)
                    publish(topic, message)
                    if self.recorder is not None:
                        self.recorder.team(topic, self.sim_time, message)
                if "poses" in self.active_topics and self.step_count % self.pose_every == 0:
                    publish("poses", self.poses.frame(self.sim_time, self.step_count))
        return done

    def _tick(self) -> None:
        self.behaviours.coupling.tick()
        self.estimator.update()
        pos, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
        matrix = self.client.getMatrixFromQuaternion(orn)
        tilt = math.acos(max(-1.0, min(1.0, matrix[8])))
        height = pos[2] - self.scene.ground_height(pos[0], pos[1])
        events = self.scorer.update(self.sim_time, self.observation(), height, tilt)
        if any(event["event"] == "fall" for event in events):
            self.behaviours.fall()
        if self.log is not None:
            self.log.state(self.step_count, self.sim_time, self.state_vector())
        if self.recorder is not None:
            self.recorder.tick(self.sim_time, self.estimator.pelvis())
        self._emit_score(events)
        publish = self.options.publish
        if publish is not None:
            publish(
                "clock",
                {"t": self.sim_time, "step": self.step_count, "wall": self.options.wall_clock()},
            )
            if "robot_state" in self.active_topics:
                snapshot = self.snapshot()
                publish("robot_state", snapshot)
                if self.recorder is not None:
                    self.recorder.team("robot_state", self.sim_time, snapshot)
        if self.ended:
            self._finish()

    def _emit_score(self, events: list[dict[str, Any]]) -> None:
        for event in events:
            event["wall_time"] = self.options.wall_clock()
            if self.log is not None:
                self.log.score(event)
            if self.recorder is not None:
                self.recorder.score(event)
            if self.options.publish is not None:
                self.options.publish("score", event)

    def _finish(self) -> None:
        if self.log is not None and not self.closed:
            final = {
                "step": self.step_count,
                "sim_time": self.sim_time,
                "end_reason": self.scorer.end_reason,
                "score": self.scorer.reached,
                "falls": self.scorer.falls,
                "state_sha256": state_digest(self.state_vector()),
            }
            if self.recorder is not None:
                self.recorder.close(final)
            self.log.close(final)
        self.closed = True

    # -- observation ----------------------------------------------------------------------
    def _hose_z(self) -> float:
        if self.scene.hose is None:
            return 0.0
        return float(self.client.getBasePositionAndOrientation(self.scene.hose)[0][2])

    def observation(self) -> Observation:
        """Return what scoring may look at now."""
        client, scene = self.client, self.scene
        positions = {"robot": tuple(client.getBasePositionAndOrientation(scene.robot)[0])}
        quantities: dict[str, float] = {"valve_angle": self.behaviours.valve.angle()}
        if scene.vehicle is not None:
            positions["vehicle"] = tuple(client.getBasePositionAndOrientation(scene.vehicle)[0])
        if scene.hose is not None:
            positions["hose"] = tuple(client.getBasePositionAndOrientation(scene.hose)[0])
            quantities["hose_lift"] = positions["hose"][2] - self.hose_start_z
        if scene.standpipe is not None and scene.hose is not None:
            quantities["hose_inlet_distance"] = self.behaviours.coupling.hose_distance()
        grasps = self.behaviours.grasps
        flags = {
            "robot_seated": self.behaviours.seat.seated,
            "hose_grasped": grasps.holding("hose") is not None,
            "hose_connected": grasps.hose_connected,
        }
        return Observation(positions, flags, quantities)  # type: ignore[arg-type]

    def state_bodies(self) -> list[int]:
        """Return the bodies whose state the state vector holds, in its order."""
        scene = self.scene
        bodies = (scene.robot, scene.vehicle, scene.hose, scene.standpipe, *scene.rubble)
        return [body for body in bodies if body is not None]

    def state_vector(self) -> list[float]:
        """Return the exact dynamic state of every moving body (for determinism and replay)."""
        client = self.client
        vector: list[float] = []
        for body in self.state_bodies():
            pos, orn = client.getBasePositionAndOrientation(body)
            linear, angular = client.getBaseVelocity(body)
            vector.extend([*pos, *orn, *linear, *angular])
            joints = client.getJointStates(body, range(client.getNumJoints(body))) or []
            for state in joints:
                vector.extend(state[:2])
        return [float(v) for v in vector]

    def snapshot(self) -> dict[str, Any]:
        """Return the robot's state as sent to controllers (lock-step replies, robot_state)."""
        estimate = self.estimator
        return {
            "t": round(self.sim_time, 6),
            "step": self.step_count,
            "pelvis": estimate.pelvis(),
            "joints": {
                "position": estimate.joint_position.tolist(),
                "velocity": estimate.joint_velocity.tolist(),
            },
            "behaviour": self.behaviours.status(),
            "score": {
                "checkpoints": self.scorer.reached,
                "falls": self.scorer.falls,
                "ended": self.ended,
                "reason": self.scorer.end_reason,
            },
        }

    def close(self) -> None:
        """End logging (if still open) and disconnect from the physics engine."""
        if not self.ended:
            self._emit_score(self.scorer.stop(self.sim_time, "closed"))
        self._finish()
        self.client.disconnect()
