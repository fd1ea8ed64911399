"""The walking and balance behaviour: ZMP preview control and leg IK, through the joints only.

As Boston Dynamics' behaviour library did for Atlas in the VRC, it turns "walk to this pose"
into footsteps, a ZMP reference, a centre-of-mass trajectory (preview control on the
cart-table model) and joint targets for both legs (analytic IK) at 1 kHz, with balance
feedback from the IMU (torso tilt) on the stance ankle and hip. No force acts on the robot
but gravity, contacts and its joints: walking too fast, on rubble or a slope can fall.
"""

from __future__ import annotations

import math

import numpy as np

from drcsim.control import JointController
from drcsim.footholds import Footholds
from drcsim.gait import (
    ANKLE_TO_SOLE,
    HIP_OFFSET,
    PREVIEW_DT,
    PREVIEW_S,
    THIGH,
    Foothold,
    GaitParameters,
    PreviewAxis,
    Swing,
    leg_ik,
    plan_poses,
    rotation,
    timeline,
    wrap_angle,
    zmp_point,
)
from drcsim.models.humanoid import ALL_JOINTS
from drcsim.scene import TICK_STEPS, Scene

LEGS = {
    side: [f"{side[0]}_leg_{j}" for j in ("hpz", "hpx", "hpy", "kny", "aky", "akx")]
    for side in ("left", "right")
}
TRUNK = ("back_bkz", "back_bky", "back_bkx")
ARMATURE = 0.05  # kg m2 of reflected actuator inertia at the ankle (see use_gains)
# PD gains while the walker owns the legs: stiff, and well damped (velocity feed-forward).
GAINS = {
    "hpz": (3000, 100),
    "hpx": (6000, 200),
    "hpy": (6000, 200),
    "kny": (6000, 200),
    "aky": (6000, 50),
    "akx": (6000, 50),
}
TILT_GAIN = 1.0  # ankle and hip correction per radian of pelvis tilt (IMU)
COM_GAIN = 3.0  # pelvis shift per metre of error of the measured centre of mass...
COM_VELOCITY = 0.5  # ...with this share of its velocity term (capture point)
VELOCITY_FILTER = 0.3  # per 100 Hz tick: low-pass on the measured COM velocity
CORRECTION_LIMIT = 0.08  # m
STRUGGLE_TILT = 0.12  # rad of pelvis tilt that the status reports as struggling
POSITION_TOLERANCE = 0.05
YAW_TOLERANCE = 0.08
MAX_REPLANS = 3  # plans without progress before the walk gives up
SWING_FROM_ACTUAL = 0.5  # share of the pelvis's tracking error the swing foot allows for
PLAN_STEPS = 30  # steps planned at a time: then both feet down and a fresh plan
TOUCH_FORCE = 150.0  # N on the descending swing foot that count as its touchdown...
TOUCH_HEIGHT = 0.015  # m ...when it is this much above the ground it was planned on
TOUCH_NEAR = 0.04  # m from its target: nearer, a touch is a landing; further, a scrape
STILL_SPEED = 0.05  # m/s the standing ZMP reference moves to between the feet
# The joints whose PD is given its load: all but the hip's pitch, which holds the trunk up
# as the IMU's pitch feedback has it (its load depends on where the centre of pressure really
# is: 0.5 cm ahead of the ankle, not the reference's 2 cm; given that load the pelvis leaned
# forward and in 0.8 s steps the feet landed a little shorter each step, until it fell).
LOADED = np.array([1.0, 1.0, 0.0, 1.0, 1.0, 1.0])
LINK_DOWN = np.array([0.0, 0.0, -THIGH])  # hip to knee (and knee to ankle: SHIN is as long)
FOOT_COM = np.array([0.04, 0.0, -0.06])  # the foot's centre of mass from the ankle
HIPS = {  # each hip joint in the pelvis frame (the right one mirrored)
    side: np.array([HIP_OFFSET[0], sign * HIP_OFFSET[1], HIP_OFFSET[2]])
    for side, sign in (("left", 1.0), ("right", -1.0))
}
HORIZONTAL = np.array([1.0, 1.0, 0.0])


class Walker:
    """Keeps the robot balanced on its feet and walks it to goals, through the leg joints."""

    def __init__(self, scene: Scene, controller: JointController) -> None:
        self.scene, self.controller, self.client = scene, controller, scene.client
        self.footholds = Footholds(scene)
        self.params = GaitParameters()
        self.slots = {
            side: np.array([controller.slot[n] for n in names]) for side, names in LEGS.items()
        }
        self.trunk_slots = np.array([controller.slot[n] for n in TRUNK])
        self.links = {side: scene.robot_links[f"{side[0]}_foot"] for side in ("left", "right")}
        self.link_indices = list(range(self.client.getNumJoints(scene.robot)))
        # Masses of the base and every link (fixed, unlike localInertiaDiagonal below).
        self.masses = [
            self.client.getDynamicsInfo(scene.robot, link)[0]
            for link in range(-1, len(self.link_indices))
        ]
        # What stands on a sole (N), and the weights of a leg's thigh, shin and foot.
        self.weight = sum(self.masses) * 9.81
        self.leg_weights = [
            self.client.getDynamicsInfo(scene.robot, scene.robot_links[f"l_{part}"])[0] * 9.81
            for part in ("uleg", "lleg", "foot")
        ]
        self.kp = {
            side: np.array([float(GAINS[name[6:]][0]) for name in names])
            for side, names in LEGS.items()
        }
        self.shares: dict[str, float] = {}
        self.loads: dict[str, np.ndarray] = {}
        self.use_gains()
        self.reset()

    def use_gains(self) -> None:
        """Stiffen the legs: the stock ankle gains are barely above gravity's toppling rate."""
        for side in ("l", "r"):
            for part in ("foot", "talus"):
                # Reflected actuator (rotor) inertia, as a physics engine's "armature": without
                # it the light foot cannot take stiff explicit PD gains at 1 kHz.
                self.client.changeDynamics(
                    self.scene.robot,
                    self.scene.robot_links[f"{side}_{part}"],
                    localInertiaDiagonal=[ARMATURE] * 3,
                )
        for names in LEGS.values():
            for name in names:
                kp, kd = GAINS[name[6:]]
                self.controller.set_gains(name, kp, 0.0, kd)

    # -- state from the robot -------------------------------------------------------------
    def _foot(self, side: str) -> Foothold:
        state = self.client.getLinkState(self.scene.robot, self.links[side])
        yaw = self.client.getEulerFromQuaternion(state[5])[2]
        x, y, z = state[4]
        return Foothold(x, y, z - ANKLE_TO_SOLE, yaw)

    def _com(self) -> np.ndarray:
        """Return the whole robot's centre of mass in the world frame (from the links' poses)."""
        client, robot = self.client, self.scene.robot
        places = [client.getBasePositionAndOrientation(robot)[0]]
        places += [state[0] for state in client.getLinkStates(robot, self.link_indices)]
        total, moment = 0.0, np.zeros(3)
        for mass, where in zip(self.masses, places, strict=True):
            total, moment = total + mass, moment + mass * np.array(where)
        return moment / total

    def _com_offset(self) -> np.ndarray:
        pos, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
        inverse = np.array(self.client.getMatrixFromQuaternion(orn)).reshape(3, 3).T
        return inverse @ (self._com() - np.array(pos))

    def _whole_com(self) -> np.ndarray:
        return self._com()[:2]

    def reset(self) -> None:
        """Take the robot as it stands now: feet where they are, the COM above them."""
        self.feet = {side: self._foot(side) for side in ("left", "right")}
        self.offset = self._com_offset()
        pos, _ = self.client.getBasePositionAndOrientation(self.scene.robot)
        yaw = self._yaw()
        com = np.array(pos) + rotation(0, 0, yaw) @ self.offset
        height = float(self.offset[2]) + self.params.pelvis_height
        self.axes = (PreviewAxis(height, float(com[0])), PreviewAxis(height, float(com[1])))
        self.com = com[:2].copy()
        self.still = com[:2].copy()  # the standing ZMP reference: from here to the feet
        self.zmp: list[tuple[float, float]] = []
        self.swings: list[Swing] = []
        self.tick = 0
        self.steps = 0
        self.goal: tuple[float, float, float] | None = None
        # a goal sent mid-walk, taken at the end of the current plan (both feet down, at rest)
        self.next_goal: tuple[tuple[float, float, float], GaitParameters] | None = None
        self.status = "standing"
        self.replans = 0
        self.pelvis_z = float(pos[2])
        self.com_from = self.com.copy()
        self.com_to = self.com.copy()
        self.last_angles: dict[str, np.ndarray] = {}
        self.velocity = np.zeros(2)
        self.tilt = 0.0
        self.active: Swing | None = None
        self.com_measured = self._whole_com()
        self.correction_from = np.zeros(2)
        self.correction_to = np.zeros(2)

    def _yaw(self) -> float:
        _, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
        return float(self.client.getEulerFromQuaternion(orn)[2])

    # -- planning -------------------------------------------------------------------------
    def walk_to(self, goal: tuple[float, float, float], params: GaitParameters) -> None:
        """Plan footsteps from where the feet are to `goal` (pelvis x, y, yaw) and start."""
        self.params = params.checked()
        self.goal = goal
        self.feet = {side: self._foot(side) for side in ("left", "right")}
        # Start from the measured centre of mass, at rest (the robot stands on both feet).
        measured = self._whole_com()
        for index, (axis, value) in enumerate(zip(self.axes, measured, strict=True)):
            axis.c = np.array([float(value), float(self.velocity[index]), 0.0])
            axis.error = 0.0
        self.com = self.com_from = self.com_to = measured.copy()
        pos, _ = self.client.getBasePositionAndOrientation(self.scene.robot)
        self.start_distance = math.hypot(goal[0] - pos[0], goal[1] - pos[1])
        left, right = self.feet["left"], self.feet["right"]
        mid = ((left.x + right.x) / 2, (left.y + right.y) / 2, self._mid_yaw())
        # A stretch at a time, then both feet down and a fresh plan from where the feet
        # really are: errors do not pile up over a long walk.
        poses = plan_poses(mid, goal, self.params.step_length)[:PLAN_STEPS]
        start = (float(self.com[0]), float(self.com[1]))
        self.zmp, self.swings = timeline(
            self.feet, poses, self.params, start, self.scene.ground_height, self.footholds.place
        )
        for swing in self.swings:
            swing.floor = self.footholds.floor(swing)
        self.tick = 0
        self.status = "walking"

    def redirect(self, goal: tuple[float, float, float], params: GaitParameters) -> None:
        """Walk to `goal` instead: now if standing, else when the current plan's steps are done.

        Replanning mid-swing planned from a foot still in the air as if it stood and felled
        the robot; so did replanning just after a landing with the body still moving (tried).
        A plan's end has both feet down and the COM at rest between them.
        """
        if self.status != "walking":
            self.replans = 0
            self.walk_to(goal, params)
        else:
            self.next_goal = (goal, params.checked())

    def _mid_yaw(self) -> float:
        a, b = self.feet["left"].yaw, self.feet["right"].yaw
        return math.atan2(math.sin(a) + math.sin(b), math.cos(a) + math.cos(b))

    # -- per step -------------------------------------------------------------------------
    def apply(self) -> None:
        """Compute this physics step's leg joint targets."""
        self.steps += 1
        if self.steps % TICK_STEPS == 1 or TICK_STEPS == 1:
            self._pattern_tick()
        self._joints()

    def _pattern_tick(self) -> None:
        horizon = round(PREVIEW_S / PREVIEW_DT)
        if self.zmp:
            ahead = self.zmp[self.tick : self.tick + horizon]
            ahead += [self.zmp[-1]] * (horizon - len(ahead))
            self.still = np.array(ahead[0])
        else:
            # Standing: the ZMP (and so the COM) between the feet where they really are, not
            # wherever the COM happens to be (that let a standing robot drift off its feet).
            # It moves there at STILL_SPEED: a reference that jumped there when a plan ended
            # (by how far the feet had landed off their footholds) kicked the robot, both feet
            # slid and on a low-friction floor it fell.
            left, right = (self._foot(side) for side in ("left", "right"))
            target = np.array([(left.x + right.x) / 2, (left.y + right.y) / 2])
            limit = STILL_SPEED * PREVIEW_DT
            self.still = self.still + np.clip(target - self.still, -limit, limit)
            ahead = [(float(self.still[0]), float(self.still[1]))] * horizon
        future = np.array(ahead)
        self.com_from = self.com_to
        self.com_to = np.array([self.axes[0].step(future[:, 0]), self.axes[1].step(future[:, 1])])
        self.active = next((w for w in self.swings if w.first <= self.tick < w.last), None)
        if self.active is not None:
            self._check_touchdown(self.active)
        for swing in self.swings:
            if swing.last == self.tick:
                if swing.touched is not None:
                    self._land(swing, swing.touched)
                self.feet[swing.side] = swing.end
        self.shares = self._shares(future[0])
        if self.zmp and self.tick >= len(self.zmp) - 1:
            self._finish()
        else:
            self.tick += 1

    def _shares(self, zmp: np.ndarray) -> dict[str, float]:
        """Return the share of the body's weight on each foot, from the ZMP reference."""
        if self.active is not None:
            stance = "right" if self.active.side == "left" else "left"
            return {stance: 1.0, self.active.side: 0.0}
        left = np.array(zmp_point(self.feet["left"], "left"))
        right = np.array(zmp_point(self.feet["right"], "right"))
        span = right - left
        length = float(span @ span)
        to_right = 0.5 if length < 1e-9 else float((zmp - left) @ span) / length
        to_right = min(1.0, max(0.0, to_right))
        return {"left": 1.0 - to_right, "right": to_right}

    def _check_touchdown(self, swing: Swing) -> None:
        """Stop lowering the swing foot where it meets something (a block, a bump)."""
        if swing.touched is not None:
            return
        span = max(1, swing.last - swing.first)
        if (self.tick - swing.first) / span < 0.5:
            return  # rising: a touch now is a stub, not a landing
        link = self.links[swing.side]
        force = sum(point[9] for point in self.client.getContactPoints(self.scene.robot, -1, link))
        real = self._foot(swing.side)
        # Only a touch above the planned ground counts: on the plan's ground the step ends
        # as planned (taking where the foot touched there let errors pile up step by step).
        near = math.hypot(real.x - swing.end.x, real.y - swing.end.y) < TOUCH_NEAR
        if force > TOUCH_FORCE and near and real.z > swing.end.z + TOUCH_HEIGHT:
            swing.touched = Foothold(real.x, real.y, real.z, swing.end.yaw)

    def _land(self, swing: Swing, where: Foothold) -> None:
        """The step ended where the foot touched down: the foot's next step starts there."""
        swing.end = where
        later = [w for w in self.swings if w.side == swing.side and w.first > swing.first]
        if later:
            later[0].start = where

    def _finish(self) -> None:
        self.zmp, self.swings, self.tick = [], [], 0
        if self.next_goal is not None:  # the plan's steps have landed, the COM is at rest
            (self.goal, self.params), self.next_goal = self.next_goal, None
            self.replans = 0
        if self.goal is None:
            return
        pos, _ = self.client.getBasePositionAndOrientation(self.scene.robot)
        gx, gy, gyaw = self.goal
        off = math.hypot(gx - pos[0], gy - pos[1])
        yaw_off = abs(wrap_angle(gyaw - self._yaw()))
        if off <= POSITION_TOLERANCE and yaw_off <= YAW_TOLERANCE:
            self.status, self.goal = "done", None
        elif off < self.start_distance - 0.1 or self.replans < MAX_REPLANS:
            # Progress, or a few tries at the last centimetres: plan the next stretch.
            if off >= self.start_distance - 0.1:
                self.replans += 1
            self.walk_to(self.goal, self.params)
        else:
            self.status, self.goal = f"blocked: {off:.2f} m short of the goal", None

    def _swing_foot(self, swing: Swing) -> Foothold:
        if swing.touched is not None:
            return swing.touched
        span = max(1, swing.last - swing.first)
        # The same instant as the COM's interpolation (self.tick is already the next tick).
        share = ((self.steps - 1) % TICK_STEPS + 1) / TICK_STEPS
        tau = min(1.0, max(0.0, (self.tick - 1 + share - swing.first) / span))
        s = tau * tau * (3 - 2 * tau)
        a, b = swing.start, swing.end
        dyaw = wrap_angle(b.yaw - a.yaw)
        # sin^2: the foot comes down at no speed (sin's 0.3 m/s touchdown jolted the robot).
        lift = self.params.step_height * math.sin(math.pi * tau) ** 2
        z = a.z + (b.z - a.z) * s + lift
        if swing.floor:  # never lower than what the sole is passing over (a block's top)
            k = min(9, int(s * 10))
            z = max(z, swing.floor[k], swing.floor[k + 1])
        return Foothold(a.x + (b.x - a.x) * s, a.y + (b.y - a.y) * s, z, a.yaw + dyaw * s)

    def _joints(self) -> None:
        # The pattern runs at 100 Hz; the joints follow its COM interpolated at 1 kHz.
        share = ((self.steps - 1) % TICK_STEPS + 1) / TICK_STEPS
        self.com = self.com_from + (self.com_to - self.com_from) * share
        feet = dict(self.feet)
        swing = self.active
        if swing is not None:
            feet[swing.side] = self._swing_foot(swing)
        yaw = math.atan2(
            sum(math.sin(f.yaw) for f in feet.values()), sum(math.cos(f.yaw) for f in feet.values())
        )
        ground = min(self.feet["left"].z, self.feet["right"].z)
        if swing is not None:
            ground = self.feet["left" if swing.side == "right" else "right"].z
        self.pelvis_z += (ground + self.params.pelvis_height - self.pelvis_z) * 0.01
        body = rotation(0.0, 0.0, yaw)
        pelvis = self._pelvis_target(body)
        # Balance from the IMU: tilt the legs against the pelvis's roll and pitch.
        where, orn = self.client.getBasePositionAndOrientation(self.scene.robot)
        roll, pitch, real_yaw = self.client.getEulerFromQuaternion(orn)
        self.tilt = math.hypot(roll, pitch)
        for side, foot in feet.items():
            if swing is not None and swing.side == side:
                # The swing foot goes to its world target from where the pelvis really is
                # (and how it is really turned: a stance foot that slipped in yaw is not
                # copied into the next footstep).
                base = np.array(where)
                real = pelvis + SWING_FROM_ACTUAL * (base - pelvis) * HORIZONTAL
                turned = rotation(0.0, 0.0, real_yaw)
                self._leg(side, foot, real, turned, (0.0, 0.0), (roll, pitch))
            else:
                self._leg(side, foot, pelvis, body, (roll, pitch), (roll, pitch))
        self.controller.set_slot_positions(self.trunk_slots, np.zeros(len(TRUNK)))

    def _pelvis_target(self, body: np.ndarray) -> np.ndarray:
        """Return where the pelvis should be for the COM plan, corrected by COM feedback."""
        com_to_pelvis = body @ self.offset
        # Centre-of-mass feedback: steer the pelvis against the measured COM's (and capture
        # point's) error, the COM measured from the links' poses (kinematics and IMU).
        omega = math.sqrt(9.81 / (float(self.offset[2]) + self.params.pelvis_height))
        share = ((self.steps - 1) % TICK_STEPS + 1) / TICK_STEPS
        if share == 1 / TICK_STEPS:
            ref_velocity = (self.com_to - self.com_from) / (TICK_STEPS * self.controller.timestep)
            whole = self._whole_com()
            self.velocity += (
                (whole - self.com_measured) / (TICK_STEPS * self.controller.timestep)
                - self.velocity
            ) * VELOCITY_FILTER
            self.com_measured = whole
            measured = self.com_measured + COM_VELOCITY * self.velocity / omega
            wanted = self.com_from + COM_VELOCITY * ref_velocity / omega
            self.correction_from = self.correction_to
            self.correction_to = np.clip(
                COM_GAIN * (measured - wanted), -CORRECTION_LIMIT, CORRECTION_LIMIT
            )
        # Measured at 100 Hz, the correction moves to its new value over the next 10 ms: one
        # that jumped every tick jolted the stance foot (hundreds of newtons; it spun in yaw).
        correction = self.correction_from + (self.correction_to - self.correction_from) * share
        target = self.com - correction
        return np.array([target[0] - com_to_pelvis[0], target[1] - com_to_pelvis[1], self.pelvis_z])

    def _leg(
        self,
        side: str,
        foot: Foothold,
        pelvis: np.ndarray,
        body: np.ndarray,
        ankle_tilt: tuple[float, float],
        hip_tilt: tuple[float, float],
    ) -> None:
        """Set one leg's joint targets (IK plus tilt feedback) and velocity feed-forward."""
        hip = pelvis + body @ HIPS[side]
        sole = self.footholds.sole(foot)
        ankle = np.array([foot.x, foot.y, foot.z]) + sole @ np.array([0.0, 0.0, ANKLE_TO_SOLE])
        angles = np.array(leg_ik(hip, body, ankle, sole))
        angles[4] += TILT_GAIN * ankle_tilt[1]  # stance ankle: the ankle strategy
        angles[5] += TILT_GAIN * ankle_tilt[0]
        angles[2] += TILT_GAIN * hip_tilt[1] * 0.5
        angles[1] += TILT_GAIN * hip_tilt[0] * 0.5
        # The body's weight on a stance leg: each joint's PD must hold its share of the load,
        # and stiff as it is, without this it gives way under it (the stance knee by 0.03 rad,
        # which leaned the pelvis back and sent every swing foot 4 cm past its foothold).
        # The load changes slowly: it is worked out at the pattern's 100 Hz (a tenth the CPU).
        if self.steps % TICK_STEPS == 1 or TICK_STEPS == 1 or side not in self.loads:
            self.loads[side] = self._load(side, hip, body, angles, foot)
        self.controller.set_slot_positions(self.slots[side], angles + self.loads[side])
        # Velocity feed-forward: the damping resists only the tracking error, not motion.
        previous = self.last_angles.get(side, angles)
        velocity = (angles - previous) / self.controller.timestep
        self.controller.target_velocity[self.slots[side]] = velocity
        self.last_angles[side] = angles

    def _load(
        self, side: str, hip: np.ndarray, body: np.ndarray, angles: np.ndarray, foot: Foothold
    ) -> np.ndarray:
        """Return the joint offsets that hold this leg's share of the body's weight.

        The ground pushes up under the foot (at its ZMP point) with the share of the weight
        the ZMP reference puts on it, and the leg's own links hang below each joint; each
        joint needs the moment of those forces about its axis (statics, J^T F), which its PD
        gives only after an error of torque / kp.
        """
        share = self.shares.get(side, 0.0)
        hpz, hpx, hpy, kny, aky, _ = angles
        turn = body @ rotation(0.0, 0.0, hpz)
        roll = turn @ rotation(hpx, 0.0, 0.0)
        thigh = roll @ rotation(0.0, hpy, 0.0)
        knee = hip + thigh @ LINK_DOWN
        shin = thigh @ rotation(0.0, kny, 0.0)
        ankle = knee + shin @ LINK_DOWN
        talus = shin @ rotation(0.0, aky, 0.0)
        axis = np.array((turn[:, 2], roll[:, 0], thigh[:, 1], shin[:, 1], talus[:, 1], talus[:, 0]))
        places = np.array((hip, hip, hip, knee, ankle, ankle))
        cx, cy = zmp_point(foot, side)
        # Vertical forces (N, up) and where they act: the ground's under the foot, and the
        # weights of the thigh, shin and foot (each joint feels those below it only).
        loads = (
            (share * self.weight, np.array([cx, cy, foot.z]), 6),
            (-self.leg_weights[0], hip + thigh @ (LINK_DOWN / 2), 3),
            (-self.leg_weights[1], knee + shin @ (LINK_DOWN / 2), 4),
            (-self.leg_weights[2], ankle + talus @ FOOT_COM, 6),
        )
        torques = np.zeros(6)
        for force, where, below in loads:
            lever = where - places[:below]
            # The moment of a vertical force about each axis (r x F has no z part).
            torques[:below] -= force * (
                axis[:below, 0] * lever[:, 1] - axis[:below, 1] * lever[:, 0]
            )
        return torques * LOADED / self.kp[side]

    def release(self) -> None:
        """Give the legs back: stock gains, no velocity feed-forward."""
        for names in LEGS.values():
            for name in names:
                slot = self.controller.slot[name]
                self.controller.target_velocity[slot] = 0.0
                spec = ALL_JOINTS[slot]
                self.controller.set_gains(name, spec.kp, 0.0, spec.kd)

    def describe(self) -> str:
        """Return the walk status, saying when balance is struggling."""
        if self.status == "walking" and self.tilt > STRUGGLE_TILT:
            return f"walking (struggling: tilted {self.tilt:.2f} rad)"
        return self.status
