"""VRC-style behaviours: stand, walk to a pose, reach, grasp/release, vehicle, valve."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drcsim.assists import Coupling, Grasps, Harness, Seat
from drcsim.control import JointController
from drcsim.driver import DriverLimbs
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.gait import GaitParameters, wrap_angle
from drcsim.models import humanoid
from drcsim.reach import ARM_JOINTS, REACH_EVERY, Reach
from drcsim.scene import Scene
from drcsim.valve import Valve
from drcsim.walker import Walker

GAIT_KEYS = ("step_length", "step_height", "step_time", "double_support", "stance_width")
WALK_SPEED = 0.8  # m/s on paved ground
TURN_RATE = 0.8  # rad/s
STRIDE = 0.6  # metres per gait cycle
POSITION_TOLERANCE = 0.04
YAW_TOLERANCE = 0.04
MAX_LEAD = 0.15  # how far the harness may lead the pelvis before walking waits
SETTLE_STEPS = 3000  # physics steps the walk may spend closing the last centimetres
PUSH_LIMIT = 150.0  # N of contact force against a movable object that stops a walk
LEG_JOINTS = [s.name for s in humanoid.BODY_JOINTS if "_leg_" in s.name]
TRUNK_JOINTS = ["back_bkz", "back_bky", "back_bkx", "neck_ry"]


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
        self.valve = Valve(scene, controller, self.grasps)
        self.driver = DriverLimbs(scene, controller, self.grasps)
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
        # "harness" (the balance assist carries the pelvis) or "joints" (the walker balances
        # and walks through the leg joints only; experimental, see the README).
        self.balance = "harness"
        self.walker: Walker | None = None
        body = LEG_JOINTS + TRUNK_JOINTS
        self._body_slots = np.array([controller.slot[name] for name in body])
        self._stand_targets = np.array([humanoid.STAND_POSTURE.get(n, 0.0) for n in body])
        self._sit_targets = np.array([humanoid.SIT_POSTURE.get(n, 0.0) for n in body])
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
        return self.valve.owner(joint) or self.driver.owner(joint)

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
        if name in ("none", "enter_vehicle") or (
            name in ("stand", "walk") and params.get("balance", "harness") == "harness"
        ):
            self._use_harness_balance()
        if name == "none":
            self.mode = "none"
            self.harness.release()
            self.reaches.clear()
        elif name in ("stand", "walk") and params.get("balance") == "joints":
            self._joint_balance(name, params, fallen)
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
            self._free_arm(side)
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
            self._free_arm(params["hand"])
            posture = humanoid.SIT_POSTURE if self.seat.seated else humanoid.STAND_POSTURE
            self.controller.set_positions(
                {j: posture.get(j, 0.0) for j in ARM_JOINTS[params["hand"]]}
            )
        elif name == "grasp":
            grasped = self.grasps.close(params["hand"])
            return {"grasped": grasped, **({} if grasped else {"note": "closed on nothing"})}
        elif name == "release":
            self._free_arm(params["hand"])
            self.grasps.open(params["hand"])
        elif name == "enter_vehicle":
            self.seat.enter()
            self.mode = "seated"
            self.harness.release()
            self.reaches.clear()
        elif name == "exit_vehicle":
            self.seat.check_exit()
            self.driver.stop()
            x, y, yaw = self.seat.exit()
            self.pose_cmd = [x, y, yaw]
            self.mode, self.walk_status = "stand", "idle"
        elif name == "drive":
            if not self.seat.seated or self.drive is None:
                raise CommandError("drive needs the robot in the driver seat")
            self.reaches.clear()
            self.driver.set_targets(
                float(params.get("steering_wheel", 0.0)),
                float(params.get("throttle", 0.0)),
                float(params.get("brake", 0.0)),
                bool(params.get("hand_brake", False)),
                str(params.get("direction", "neutral")),
            )
        elif name == "turn_valve":
            # Started first: a refused turn (hand not at the valve) leaves the reach as it was.
            self.valve.start(params["hand"], float(params.get("angle", 2 * math.pi)))
            self.reaches.pop(params["hand"], None)
        else:
            raise CommandError(f"unknown behaviour {name!r}")
        return {}

    def _free_arm(self, side: str) -> None:
        """Stop the valve or driving behaviour that uses this arm (its hand lets go)."""
        self.valve.cancel(side)
        self.driver.stop(side)

    def _use_harness_balance(self) -> None:
        if self.walker is not None and self.balance == "joints":
            self.walker.release()
        self.balance = "harness"

    def _joint_balance(self, name: str, params: dict[str, Any], fallen: bool) -> None:
        """Stand or walk with the walker: no harness, only the leg joints hold the robot."""
        if fallen:
            self._stand(recover=True)  # the recovery assist, then balance by the joints
        self.harness.release()
        if self.walker is None:
            self.walker = Walker(self.scene, self.controller)
        elif self.balance != "joints":
            self.walker.use_gains()
        if self.balance != "joints" or fallen:
            self.walker.reset()
        self.balance = "joints"
        if name == "stand":
            self.mode, self.walk_status = "stand", "idle"
            return
        gait = {k: float(params[k]) for k in GAIT_KEYS if k in params}
        goal = params["pose"]
        self.walker.walk_to((goal[0], goal[1], goal[2]), GaitParameters(**gait))
        self.mode, self.walk_status = "walk", "walking"

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
        if self.balance == "joints" and self.walker is not None and self.mode in ("stand", "walk"):
            self.walker.apply()
            if self.mode == "walk":
                self.walk_status = self.walker.describe()
                if self.walker.status != "walking":
                    self.mode = "stand"
        elif self.mode in ("stand", "walk"):
            if self.mode == "walk":
                self._walk_step()
            x, y, yaw = self.pose_cmd
            z = humanoid.STAND_PELVIS_HEIGHT + self.scene.ground_height(x, y)
            self.harness.hold(x, y, z, yaw)
            self._legs()
        elif self.mode == "seated":
            self.controller.set_slot_positions(self._body_slots, self._sit_targets)
        for reach in self.reaches.values():
            if self.steps % REACH_EVERY == 0:
                reach.update()
            reach.apply()
        self.valve.apply(self.steps)
        self.driver.apply(self.steps)
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
        heading_error = wrap_angle(math.atan2(gy - y, gx - x) - yaw) if distance > 1e-6 else 0.0
        turn, advance = 0.0, 0.0
        if distance > POSITION_TOLERANCE / 2:
            if abs(heading_error) > 0.3 and distance > 0.2:
                turn = math.copysign(min(TURN_RATE * dt, abs(heading_error)), heading_error)
            else:
                turn = max(-TURN_RATE * dt, min(TURN_RATE * dt, heading_error * dt * 2.0))
                advance = min(speed * dt, distance)
        else:
            yaw_error = wrap_angle(gyaw - yaw)
            if abs(yaw_error) <= YAW_TOLERANCE / 2:
                self._settle(pos)
                return
            turn = math.copysign(min(TURN_RATE * dt, abs(yaw_error)), yaw_error)
        yaw = wrap_angle(yaw + turn)
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
        if (
            math.hypot(ex, ey) <= POSITION_TOLERANCE / 2
            and abs(wrap_angle(gyaw - yaw)) <= YAW_TOLERANCE
        ):
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
        self.pose_cmd[2] = wrap_angle(
            self.pose_cmd[2] + max(-0.001, min(0.001, wrap_angle(gyaw - yaw) * gain))
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
            "balance": self.balance,
            "walk": self.walk_status,
            "reach": {side: reach.status for side, reach in self.reaches.items()},
            "held": {hand: name for hand, (_, name) in self.grasps.held.items()},
            "seated": self.seat.seated,
            "hose_connected": self.grasps.hose_connected,
            "valve": self.valve.status_word,
            "drive": self.driver.status(),
        }
