"""VRC-style behaviours: stand, walk to a pose, reach, grasp/release, vehicle, valve."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drcsim.assists import Coupling, Grasps, Harness, Seat, Valve
from drcsim.control import JointController
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.models import humanoid
from drcsim.scene import Scene

WALK_SPEED = 0.8  # m/s on paved ground
TURN_RATE = 0.8  # rad/s
STRIDE = 0.6  # metres per gait cycle
POSITION_TOLERANCE = 0.04
YAW_TOLERANCE = 0.04
MAX_LEAD = 0.15  # how far the harness may lead the pelvis before walking waits
SETTLE_STEPS = 3000  # physics steps the walk may spend closing the last centimetres
PUSH_LIMIT = 150.0  # N of contact force against a movable object that stops a walk
REACH_EVERY = 20  # physics steps between task-space IK updates (50 Hz)
REACH_GAIN = 0.3
REACH_TOLERANCE = 0.02
LEG_JOINTS = [s.name for s in humanoid.BODY_JOINTS if "_leg_" in s.name]
TRUNK_JOINTS = ["back_bkz", "back_bky", "back_bkx", "neck_ry"]
ARM_JOINTS = {
    side: [s.name for s in humanoid.BODY_JOINTS if s.name.startswith(f"{side[0]}_arm")]
    for side in ("left", "right")
}


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


class Reach:
    """Moves one hand (or the object it holds) to a world point by task-space integral IK."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        side: str,
        target: list[float],
        tool: bool,
        grasps: Grasps,
        frame: str = "world",
    ) -> None:
        self.scene, self.controller, self.side = scene, controller, side
        self.target = np.array(target, dtype=float)
        self.frame = frame
        self.link = scene.robot_links[humanoid.HAND_LINKS[side]]
        self.slots = [controller.slot[name] for name in ARM_JOINTS[side]]
        self.joint_targets = controller.position[self.slots].copy()
        client = scene.client
        # Points are kept in the hand's URDF link frame: calculateJacobian works in that frame.
        link_state = client.getLinkState(scene.robot, self.link)
        self.local = list(link_state[2])  # the palm (the hand link's centre of mass)
        self.status = "reaching"
        if tool and grasps.holding("hose") == side and scene.hose is not None:
            frame_pos, frame_orn = link_state[4], link_state[5]
            obj_pos, _ = client.getBasePositionAndOrientation(scene.hose)
            inv_pos, inv_orn = client.invertTransform(frame_pos, frame_orn)
            self.local = list(client.multiplyTransforms(inv_pos, inv_orn, obj_pos, [0, 0, 0, 1])[0])

    def point(self) -> np.ndarray:
        """Return the world position of the point being moved."""
        client = self.scene.client
        state = client.getLinkState(self.scene.robot, self.link)
        return np.array(client.multiplyTransforms(state[4], state[5], self.local, [0, 0, 0, 1])[0])

    def update(self) -> None:
        """One IK iteration from the measured error; the joint PIDs do the rest."""
        client, controller = self.scene.client, self.controller
        target = self.target
        if self.frame == "pelvis":
            pos, orn = client.getBasePositionAndOrientation(self.scene.robot)
            target = np.array(client.multiplyTransforms(pos, orn, target.tolist(), [0, 0, 0, 1])[0])
        error = target - self.point()
        self.status = "reached" if np.linalg.norm(error) < REACH_TOLERANCE else "reaching"
        positions = [0.0] * client.getNumJoints(self.scene.robot)
        for slot, index in enumerate(controller.indices):
            positions[index] = float(controller.position[slot])
        zeros = [0.0] * len(positions)
        linear, _ = client.calculateJacobian(
            self.scene.robot, self.link, self.local, positions, zeros, zeros
        )
        # pybullet returns a floating base's Jacobian in the base frame: rotate it to world.
        _, base_orn = client.getBasePositionAndOrientation(self.scene.robot)
        jacobian = np.array(client.getMatrixFromQuaternion(base_orn)).reshape(3, 3) @ np.array(
            linear
        )
        offset = jacobian.shape[1] - len(positions)  # a floating base adds 6 columns first
        columns = [offset + controller.indices[slot] for slot in self.slots]
        arm = jacobian[:, columns]
        damping = 0.05**2 * np.eye(3)
        step = arm.T @ np.linalg.solve(arm @ arm.T + damping, error)
        step = np.clip(REACH_GAIN * step, -0.15, 0.15)
        lower, upper = controller.lower[self.slots], controller.upper[self.slots]
        self.joint_targets = np.clip(self.joint_targets + step, lower, upper)

    def apply(self) -> None:
        """Hold the arm's joint targets."""
        for slot, value in zip(self.slots, self.joint_targets, strict=True):
            self.controller.set_position(self.controller.names[slot], float(value))


class Behaviours:
    """The behaviour layer between team commands and the joint controller."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        drive: VehicleDrive | None,
        assists: dict[str, float],
    ) -> None:
        self.scene, self.controller, self.drive = scene, controller, drive
        self.client = scene.client
        self.harness = Harness(self.client, scene.robot)
        self.grasps = Grasps(scene, controller)
        self.seat = Seat(scene, controller, drive)
        self.valve = Valve(scene, self.grasps)
        self.coupling = Coupling(
            scene,
            self.grasps,
            assists.get("coupling_distance", 0.08),
            int(assists.get("coupling_hold_s", 0.2) * 100),
        )
        self.mode = "stand"
        self.walk_status = "idle"
        self.walk_goal: tuple[float, float, float] | None = None
        self.phase = 0.0
        self.settle_steps = 0
        pos, orn = self.client.getBasePositionAndOrientation(scene.robot)
        self.pose_cmd = [pos[0], pos[1], self.client.getEulerFromQuaternion(orn)[2]]
        self.reaches: dict[str, Reach] = {}
        self.steps = 0
        body = LEG_JOINTS + TRUNK_JOINTS
        self._body_slots = np.array([controller.slot[name] for name in body])
        self._stand_targets = np.array([humanoid.STAND_POSTURE.get(n, 0.0) for n in body])
        gait = [f"{side}_leg_{joint}" for side in "lr" for joint in ("hpy", "kny", "aky")]
        self._gait_index = np.array([body.index(name) for name in gait])
        controller.reset_to(humanoid.STAND_POSTURE)

    # -- joint ownership ----------------------------------------------------------------------
    def owner(self, joint: str) -> str | None:
        """Return the behaviour that drives `joint` now (it refuses team commands), if any."""
        if joint in LEG_JOINTS or joint in TRUNK_JOINTS:
            return self.mode if self.mode in ("stand", "walk", "seated") else None
        for side, reach in self.reaches.items():
            if joint in ARM_JOINTS[side]:
                return f"reach ({reach.side} hand)"
        return None

    def check_free(self, joints: list[str]) -> None:
        """Raise CommandError naming every joint in `joints` that a behaviour owns."""
        owned = [(name, owner) for name in joints if (owner := self.owner(name)) is not None]
        if owned:
            listed = ", ".join(f"{name} (owned by {owner})" for name, owner in owned)
            raise CommandError(
                f"refused: {listed}; send behaviour 'none' (or 'arm_rest' for an arm) "
                "to take the joints back"
            )

    # -- commands -------------------------------------------------------------------------
    def command(self, name: str, params: dict[str, Any], fallen: bool) -> dict[str, Any]:
        """Start behaviour `name`; return details for the reply; raise CommandError if refused."""
        if self.seat.seated and name in ("stand", "walk", "none"):
            raise CommandError(f"{name} is not possible in the vehicle (exit_vehicle first)")
        if name == "none":
            self.mode = "none"
            self.harness.release()
            self.reaches.clear()
        elif name == "stand":
            self._stand(recover=fallen)
        elif name == "walk":
            goal = params["pose"]
            self._stand(recover=fallen)
            self.settle_steps = 0
            self.mode, self.walk_goal, self.walk_status = (
                "walk",
                (goal[0], goal[1], goal[2]),
                "walking",
            )
        elif name == "reach":
            side = params["hand"]
            self.reaches[side] = Reach(
                self.scene,
                self.controller,
                side,
                params["target"],
                bool(params.get("tool", False)),
                self.grasps,
                str(params.get("frame", "world")),
            )
        elif name == "arm_rest":
            self.reaches.pop(params["hand"], None)
            posture = humanoid.SIT_POSTURE if self.seat.seated else humanoid.STAND_POSTURE
            self.controller.set_positions(
                {j: posture.get(j, 0.0) for j in ARM_JOINTS[params["hand"]]}
            )
        elif name == "grasp":
            return {"grasped": self.grasps.close(params["hand"])}
        elif name == "release":
            self.grasps.open(params["hand"])
        elif name == "enter_vehicle":
            self.seat.enter()
            self.mode = "seated"
            self.harness.release()
            self.reaches.clear()
        elif name == "exit_vehicle":
            x, y, yaw = self.seat.exit()
            self.pose_cmd = [x, y, yaw]
            self.mode, self.walk_status = "stand", "idle"
        elif name == "drive":
            if not self.seat.seated or self.drive is None:
                raise CommandError("drive needs the robot in the driver seat")
            self.drive.set_interfaces(
                float(params.get("steering_wheel", 0.0)),
                float(params.get("throttle", 0.0)),
                float(params.get("brake", 0.0)),
                bool(params.get("hand_brake", False)),
                str(params.get("direction", "neutral")),
            )
        elif name == "turn_valve":
            self.valve.start(params["hand"], float(params.get("angle", 2 * math.pi)))
        else:
            raise CommandError(f"unknown behaviour {name!r}")
        return {}

    def _stand(self, recover: bool) -> None:
        client, robot = self.client, self.scene.robot
        pos, orn = client.getBasePositionAndOrientation(robot)
        yaw = client.getEulerFromQuaternion(orn)[2]
        if recover:
            # Recovery assist: the robot is stood up where it is (same rule for every team).
            z = humanoid.STAND_PELVIS_HEIGHT + self.scene.ground_height(pos[0], pos[1])
            client.resetBasePositionAndOrientation(
                robot, [pos[0], pos[1], z], client.getQuaternionFromEuler([0, 0, yaw])
            )
            client.resetBaseVelocity(robot, [0, 0, 0], [0, 0, 0])
            self.controller.reset_to(humanoid.STAND_POSTURE)
            self.reaches.clear()
        if self.mode != "walk":
            self.pose_cmd = [pos[0], pos[1], yaw]
        self.mode, self.walk_status = "stand", "idle"

    # -- per step -------------------------------------------------------------------------
    def apply(self) -> None:
        """Run this physics step's share of every active behaviour."""
        self.steps += 1
        if self.mode == "walk":
            self._walk_step()
        if self.mode in ("stand", "walk"):
            x, y, yaw = self.pose_cmd
            z = humanoid.STAND_PELVIS_HEIGHT + self.scene.ground_height(x, y)
            self.harness.hold(x, y, z, yaw)
            self._legs()
        elif self.mode == "seated":
            self.controller.set_positions(
                {n: humanoid.SIT_POSTURE.get(n, 0.0) for n in LEG_JOINTS + TRUNK_JOINTS}
            )
        for reach in self.reaches.values():
            if self.steps % REACH_EVERY == 0:
                reach.update()
            reach.apply()
        self.valve.apply()
        if self.drive is not None:
            self.drive.apply()

    def _legs(self) -> None:
        targets = self._stand_targets
        if self.mode == "walk":
            targets = targets.copy()
            for offset, shift in ((0, 0.0), (3, math.pi)):
                swing = math.sin(self.phase + shift)
                hip, knee = -0.3 - 0.3 * swing, 0.6 + 0.6 * max(0.0, swing)
                targets[self._gait_index[offset : offset + 3]] = (hip, knee, -(hip + knee))
        self.controller.set_slot_positions(self._body_slots, targets)

    def _walk_step(self) -> None:
        assert self.walk_goal is not None
        dt = self.controller.timestep
        pos, _ = self.client.getBasePositionAndOrientation(self.scene.robot)
        x, y, yaw = self.pose_cmd
        gx, gy, gyaw = self.walk_goal
        distance = math.hypot(gx - x, gy - y)
        patch = self.scene.terrain_at(pos[0], pos[1])
        speed = WALK_SPEED * (patch.walk_speed if patch else 1.0)
        if math.hypot(pos[0] - x, pos[1] - y) > MAX_LEAD:
            self.walk_status = "blocked"
            return
        if self.steps % 10 == 0 and (pushed := self._pushing()) is not None:
            # Walking into a movable object shoves it: stop where we are and say so.
            _, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
            self.pose_cmd = [pos[0], pos[1], self.client.getEulerFromQuaternion(orn)[2]]
            self.mode, self.walk_status = "stand", f"blocked: pushing the {pushed}"
            return
        self.walk_status = "walking"
        if self.settle_steps:
            self._settle(pos)
            return
        heading_error = _wrap(math.atan2(gy - y, gx - x) - yaw) if distance > 1e-6 else 0.0
        turn, advance = 0.0, 0.0
        if distance > POSITION_TOLERANCE / 2:
            if abs(heading_error) > 0.3 and distance > 0.2:
                turn = math.copysign(min(TURN_RATE * dt, abs(heading_error)), heading_error)
            else:
                turn = max(-TURN_RATE * dt, min(TURN_RATE * dt, heading_error * dt * 2.0))
                advance = min(speed * dt, distance)
        else:
            yaw_error = _wrap(gyaw - yaw)
            if abs(yaw_error) <= YAW_TOLERANCE / 2:
                self._settle(pos)
                return
            turn = math.copysign(min(TURN_RATE * dt, abs(yaw_error)), yaw_error)
        if advance == 0.0 and distance <= POSITION_TOLERANCE / 2:
            advance = 0.0
        yaw = _wrap(yaw + turn)
        direction = math.atan2(gy - y, gx - x) if distance > 1e-6 else yaw
        self.pose_cmd = [x + advance * math.cos(direction), y + advance * math.sin(direction), yaw]
        self.phase += 2 * math.pi * (advance / STRIDE + abs(turn) / 1.5)

    def _settle(self, pos: tuple[float, ...]) -> None:
        """At the goal on paper: `done` only once the pelvis itself is there, else correct."""
        assert self.walk_goal is not None
        gx, gy, gyaw = self.walk_goal
        _, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
        yaw = self.client.getEulerFromQuaternion(orn)[2]
        ex, ey = gx - pos[0], gy - pos[1]
        if math.hypot(ex, ey) <= POSITION_TOLERANCE / 2 and abs(_wrap(gyaw - yaw)) <= YAW_TOLERANCE:
            self.mode, self.walk_status, self.settle_steps = "stand", "done", 0
            return
        self.settle_steps += 1
        if self.settle_steps > SETTLE_STEPS:
            self.mode, self.walk_status, self.settle_steps = (
                "stand",
                "blocked: short of the goal",
                0,
            )
            return
        # Lead the pelvis by the remaining error (bounded), as a step correction would.
        gain = self.controller.timestep * 2.0
        self.pose_cmd[0] += max(-0.001, min(0.001, ex * gain))
        self.pose_cmd[1] += max(-0.001, min(0.001, ey * gain))
        self.pose_cmd[2] = _wrap(
            self.pose_cmd[2] + max(-0.001, min(0.001, _wrap(gyaw - yaw) * gain))
        )

    def _pushing(self) -> str | None:
        """Return the name of a movable object the robot pushes hard against, if any."""
        # Static props (table, standpipe, gates) cannot be shoved: the lag check covers them.
        car = self.scene.vehicle
        if car is None:
            return None
        force = sum(p[9] for p in self.client.getContactPoints(bodyA=self.scene.robot, bodyB=car))
        return "vehicle" if force > PUSH_LIMIT else None

    # -- status -------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """Return what each behaviour is doing."""
        return {
            "mode": self.mode,
            "walk": self.walk_status,
            "reach": {side: reach.status for side, reach in self.reaches.items()},
            "held": {hand: name for hand, (_, name) in self.grasps.held.items()},
            "seated": self.seat.seated,
            "hose_connected": self.grasps.hose_connected,
            "valve": self.valve.status_word,
        }
