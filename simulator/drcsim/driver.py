"""The seated robot's hands on the vehicle: the left on the steering wheel, the right on levers.

The `drive` behaviour's parameters are targets for these limbs: the left hand holds the
steering wheel's rim and the arm turns it (hand over hand past the arm's stroke), the right
hand takes the hand brake or the F/N/R switch in turn and moves it. The vehicle responds
only to where the interfaces are (driving.py).
"""

from __future__ import annotations

import math

import numpy as np

from drcsim.assists import Grasps
from drcsim.control import JointController
from drcsim.driving import DIRECTIONS
from drcsim.gait import ANKLE_TO_SOLE, SHIN, THIGH
from drcsim.handles import TOLERANCE, Handle, Turner, set_friction
from drcsim.models.vehicle import INTERFACES, PEDAL_TILT, PEDALS
from drcsim.reach import ARM_JOINTS, REACH_EVERY
from drcsim.scene import Scene
from drcsim.walker import ARMATURE, HIPS

WHEEL_RIM = 0.18  # the steering wheel's radius, metres
LEVER_GRIP = 0.1  # from a lever's pivot to where the hand holds it
FRICTION = {"steering_wheel": 2.0, "hand_brake": 6.0, "fnr_switch": 3.0}  # N m
# The left hand works the wheel's upper left quarter (angle about the column from the left,
# +y, upwards) and strokes this far either side before taking the rim again.
WHEEL_HOME = 0.7
WHEEL_STROKE = 0.9
LEVERS = ("fnr_switch", "hand_brake")
# Each foot has its pedal (two-footed driving: no foot moves between pedals).
FEET = {"throttle_pedal": "r", "brake_pedal": "l"}
SOLE_IN_FOOT = (0.04, 0.0, -ANKLE_TO_SOLE)  # the sole's centre in the foot's frame
FOOT_PITCH = PEDAL_TILT - math.pi / 2  # toes up: the sole flat on the leaning pedal
CONTACT = 0.07  # from the pedal's pivot along the plate to where the sole's centre presses
PRESS_GAIN = 0.05  # m of foot travel per rad of pedal error, per update (50 Hz)
PRESS_RANGE = (-0.04, 0.08)  # the foot's travel past the released pedal's face
# The light foot in the air cannot take the standing gains as explicit PD at 1 kHz.
ANKLE_GAINS = (150.0, 0.0, 2.0)
LEG_RATE = 2.0  # rad/s: how fast the leg's targets move


class Foot:
    """Presses one pedal with one foot through the leg's hip, knee and ankle pitch joints."""

    def __init__(self, scene: Scene, controller: JointController, pedal: str) -> None:
        self.scene, self.controller, self.pedal = scene, controller, pedal
        side = FEET[pedal]
        self.slots = np.array([controller.slot[f"{side}_leg_{j}"] for j in ("hpy", "kny", "aky")])
        self.ankle = [controller.slot[f"{side}_leg_{j}"] for j in ("aky", "akx")]
        self.hip = HIPS["left" if side == "l" else "right"]
        self.link = scene.robot_links[f"{side}_foot"]
        self.ankle_links = [scene.robot_links[f"{side}_{part}"] for part in ("talus", "foot")]
        self.press = PRESS_RANGE[0]
        self.target = 0.0  # the pedal angle wanted
        self.touching = False
        self.saved: list[tuple[float, float, float]] = []
        self.inertia: list[list[float]] = []
        self.joint_targets = controller.position[self.slots].copy()
        self.command = self.joint_targets.copy()

    def start(self) -> None:
        """Take the leg, with ankle gains the free foot can take."""
        c, client = self.controller, self.scene.client
        self.saved = [(c.kp[i], c.ki[i], c.kd[i]) for i in self.ankle]
        for slot in self.ankle:
            c.set_gains(c.names[slot], *ANKLE_GAINS)
        # The ankle actuator's reflected inertia (the walker's): without it the light foot
        # chatters at the velocity limit's full-effort brake.
        robot = self.scene.robot
        self.inertia = [list(client.getDynamicsInfo(robot, link)[2]) for link in self.ankle_links]
        for link in self.ankle_links:
            client.changeDynamics(robot, link, localInertiaDiagonal=[ARMATURE] * 3)
        self.command = c.target[self.slots].copy()
        self.update()

    def stop(self) -> None:
        """Take the foot off the pedal and give the leg its gains back."""
        self.touch(False)
        self.target, self.press = 0.0, PRESS_RANGE[0]
        for slot, gains in zip(self.ankle, self.saved, strict=True):
            self.controller.set_gains(self.controller.names[slot], *gains)
        for link, inertia in zip(self.ankle_links, self.inertia, strict=True):
            self.scene.client.changeDynamics(self.scene.robot, link, localInertiaDiagonal=inertia)

    def touch(self, enabled: bool) -> None:
        """Let the foot touch its pedal (the seated robot touches nothing else in the vehicle)."""
        scene = self.scene
        assert scene.vehicle is not None
        joint = scene.vehicle_joints[self.pedal]
        scene.client.setCollisionFilterPair(
            scene.robot, scene.vehicle, self.link, joint, int(enabled)
        )
        self.touching = enabled

    def update(self) -> None:
        """Move the foot towards where the pedal should be (feeling it: the angle's error)."""
        scene, client = self.scene, self.scene.client
        assert scene.vehicle is not None
        joint = scene.vehicle_joints[self.pedal]
        angle = float(client.getJointState(scene.vehicle, joint)[0])
        if self.target < 0.01 or not self.touching:
            self.press = max(self.press - 0.01, PRESS_RANGE[0])
        else:
            self.press += PRESS_GAIN * (self.target - angle)
            self.press = min(max(self.press, PRESS_RANGE[0]), PRESS_RANGE[1])
        pivot = client.getLinkState(scene.vehicle, joint)[4]
        pelvis_pos, pelvis_orn = client.getBasePositionAndOrientation(scene.robot)
        inv_pos, inv_orn = client.invertTransform(pelvis_pos, pelvis_orn)
        local = np.array(client.multiplyTransforms(inv_pos, inv_orn, pivot, [0, 0, 0, 1])[0])
        along = np.array([math.sin(PEDAL_TILT), 0.0, math.cos(PEDAL_TILT)])
        normal = np.array([-math.cos(PEDAL_TILT), 0.0, math.sin(PEDAL_TILT)])  # to the driver
        sole = local + CONTACT * along + (0.02 - self.press) * normal - self.hip
        if not self.touching:
            # Bring the foot up behind the pedal first; only then may it touch and press it.
            foot_pos, foot_orn = client.getLinkState(scene.robot, self.link)[4:6]
            world = client.multiplyTransforms(foot_pos, foot_orn, SOLE_IN_FOOT, [0, 0, 0, 1])[0]
            actual = np.array(client.multiplyTransforms(inv_pos, inv_orn, world, [0, 0, 0, 1])[0])
            if np.linalg.norm(actual - self.hip - sole) < 0.03:
                self.touch(True)
        c, s = math.cos(FOOT_PITCH), math.sin(FOOT_PITCH)
        ahead = SOLE_IN_FOOT[0] * c + SOLE_IN_FOOT[2] * s
        up = -SOLE_IN_FOOT[0] * s + SOLE_IN_FOOT[2] * c
        ankle_x, ankle_z = sole[0] - ahead, sole[2] - up
        reach = min(math.hypot(ankle_x, ankle_z), 0.99 * (THIGH + SHIN))
        knee = math.acos(min(1.0, (reach**2 - THIGH**2 - SHIN**2) / (2 * THIGH * SHIN)))
        hip = math.atan2(-ankle_x, -ankle_z) - math.atan2(
            SHIN * math.sin(knee), THIGH + SHIN * math.cos(knee)
        )
        targets = np.array([hip, knee, FOOT_PITCH - hip - knee])
        lower, upper = self.controller.lower[self.slots], self.controller.upper[self.slots]
        self.joint_targets = np.clip(targets, lower, upper)

    def apply(self) -> None:
        """Move the leg's joint targets towards the IK's, no faster than LEG_RATE."""
        step = LEG_RATE * self.controller.timestep
        self.command += np.clip(self.joint_targets - self.command, -step, step)
        self.controller.set_slot_positions(self.slots, self.command)


class DriverLimbs:
    """Moves the steering wheel, hand brake and F/N/R switch with the seated robot's arms."""

    def __init__(self, scene: Scene, controller: JointController, grasps: Grasps) -> None:
        self.scene, self.controller, self.grasps = scene, controller, grasps
        self.handles: dict[str, Handle] = {}
        self.targets = {"steering_wheel": 0.0, "hand_brake": 0.0, "fnr_switch": 0.0}
        self.wheel: Turner | None = None
        self.lever: Turner | None = None
        self.active: set[str] = set()  # the hands driving now
        self.feet: dict[str, Foot] = {}
        if scene.vehicle is None:
            return
        self.feet = {pedal: Foot(scene, controller, pedal) for pedal in PEDALS}
        for name in ("steering_wheel", *LEVERS):
            rim = name == "steering_wheel"
            axis, u = ((1, 0, 0), (0, 1, 0)) if rim else ((0, 1, 0), (0, 0, 1))
            handle = Handle(
                name,
                scene.vehicle,
                scene.vehicle_joints[name],
                axis,
                u,
                WHEEL_RIM if rim else LEVER_GRIP,
                rim,
            )
            self.handles[name] = handle
            grasps.handles.append(handle)
            set_friction(scene, handle, FRICTION[name])

    def set_targets(
        self, steering_wheel: float, throttle: float, brake: float, hand_brake: bool, direction: str
    ) -> None:
        """Set where the limbs put each interface (pedal fractions 0..1)."""
        wheel = INTERFACES["steering_wheel"]
        self.targets["steering_wheel"] = min(max(steering_wheel, wheel.lower), wheel.upper)
        self.targets["hand_brake"] = INTERFACES["hand_brake"].upper if hand_brake else 0.0
        self.targets["fnr_switch"] = DIRECTIONS[direction]
        for pedal, fraction in (("throttle_pedal", throttle), ("brake_pedal", brake)):
            self.feet[pedal].target = min(max(fraction, 0.0), 1.0) * INTERFACES[pedal].upper
        if "feet" not in self.active:
            for foot in self.feet.values():
                foot.start()
        self.active = {"left", "right", "feet"}

    def owner(self, joint: str) -> str | None:
        """Return the behaviour owning `joint` (an arm driving), if any."""
        for side in self.active - {"feet"}:
            if joint in ARM_JOINTS[side]:
                return f"drive ({side} hand)"
        return None

    def stop(self, side: str | None = None) -> None:
        """Take the hands and feet (or one hand) off the controls."""
        if side is None and "feet" in self.active:
            for foot in self.feet.values():
                foot.stop()
            self.active.discard("feet")
        for hand in ("left", "right"):
            if side not in (None, hand) or hand not in self.active:
                continue
            turner = self.wheel if hand == "left" else self.lever
            if turner is not None:
                turner.let_go()
            if hand == "left":
                self.wheel = None
            else:
                self.lever = None
            self.active.discard(hand)

    def apply(self, step: int) -> None:
        """Run this physics step's share of both hands and both feet."""
        if "feet" in self.active:
            for foot in self.feet.values():
                if step % REACH_EVERY == 0:
                    foot.update()
                foot.apply()
        if "left" in self.active:
            if self.wheel is None or self.wheel.status.startswith("stalled"):
                self.wheel = Turner(
                    self.scene,
                    self.controller,
                    self.grasps,
                    self.handles["steering_wheel"],
                    "left",
                    WHEEL_HOME,
                    WHEEL_STROKE,
                )
            self.wheel.goal = self.targets["steering_wheel"]
            self.wheel.apply(step)
        if "right" in self.active:
            if step % REACH_EVERY == 0:
                self._next_lever()
            if self.lever is not None:
                self.lever.apply(step)

    def _next_lever(self) -> None:
        """Keep the right hand on the lever it moves until done, then take the next one."""
        if self.lever is not None:
            self.lever.goal = self.targets[self.lever.handle.name]
        if self.lever is not None and not (
            self.lever.done() or self.lever.status.startswith("stalled")
        ):
            return
        pending = [
            name
            for name in LEVERS
            if abs(self.handles[name].angle(self.scene) - self.targets[name]) > TOLERANCE
        ]
        if not pending:
            return
        if self.lever is not None:
            if self.lever.handle.name == pending[0] and not self.lever.status.startswith("stall"):
                return
            self.lever.let_go()
        self.lever = Turner(
            self.scene, self.controller, self.grasps, self.handles[pending[0]], "right"
        )
        self.lever.goal = self.targets[pending[0]]

    def status(self) -> dict[str, str]:
        """Return what each hand does."""
        out = {}
        if self.wheel is not None:
            out["steering_wheel"] = self.wheel.status
        if self.lever is not None:
            out[self.lever.handle.name] = self.lever.status
        return out
