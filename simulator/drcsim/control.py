"""Per-joint PID position control and direct torque control, with every limit enforced."""

from __future__ import annotations

import numpy as np

from drcsim._bullet import BulletClient, pybullet
from drcsim.models.humanoid import ALL_JOINTS, JOINT_NAMES

POSITION = 0
TORQUE = 1
INTEGRAL_LIMIT = 0.2  # rad s: keeps a saturated joint from winding up


class JointController:
    """Computes joint torques each physics step: PID towards targets or commanded torques."""

    def __init__(
        self, client: BulletClient, robot: int, joint_index: dict[str, int], timestep: float
    ) -> None:
        self.client = client
        self.robot = robot
        self.timestep = timestep
        self.names = JOINT_NAMES
        self.slot = {name: slot for slot, name in enumerate(self.names)}
        self.indices = [joint_index[name] for name in self.names]
        self.lower = np.array([spec.lower for spec in ALL_JOINTS])
        self.upper = np.array([spec.upper for spec in ALL_JOINTS])
        self.max_velocity = np.array([spec.velocity for spec in ALL_JOINTS])
        self.max_effort = np.array([spec.effort for spec in ALL_JOINTS])
        self.kp = np.array([spec.kp for spec in ALL_JOINTS])
        self.ki = np.zeros(len(ALL_JOINTS))
        self.kd = np.array([spec.kd for spec in ALL_JOINTS])
        self.mode = np.full(len(ALL_JOINTS), POSITION)
        self.target = np.zeros(len(ALL_JOINTS))
        self.target_velocity = np.zeros(len(ALL_JOINTS))
        self.commanded_torque = np.zeros(len(ALL_JOINTS))
        self.integral = np.zeros(len(ALL_JOINTS))
        self.position = np.zeros(len(ALL_JOINTS))
        self.velocity = np.zeros(len(ALL_JOINTS))
        self.applied = np.zeros(len(ALL_JOINTS))
        # pybullet's default velocity motors would fight our torques: switch them off.
        client.setJointMotorControlArray(
            robot, self.indices, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(self.indices)
        )
        self.read()

    def read(self) -> None:
        """Read joint positions and velocities from the physics engine."""
        states = self.client.getJointStates(self.robot, self.indices)
        self.position = np.array([s[0] for s in states])
        self.velocity = np.array([s[1] for s in states])

    def set_position(self, name: str, value: float) -> None:
        """Switch joint `name` to PID position control towards `value` (clamped to limits)."""
        slot = self.slot[name]
        self.mode[slot] = POSITION
        self.target[slot] = min(max(value, self.lower[slot]), self.upper[slot])

    def set_slot_positions(self, slots: np.ndarray, values: np.ndarray) -> None:
        """Switch the joints at `slots` to position control towards `values` (clamped)."""
        self.mode[slots] = POSITION
        self.target[slots] = np.clip(values, self.lower[slots], self.upper[slots])

    def set_positions(self, targets: dict[str, float]) -> None:
        """Switch several joints to position control."""
        for name, value in targets.items():
            self.set_position(name, value)

    def set_torque(self, name: str, value: float) -> None:
        """Switch joint `name` to direct torque control (clamped to its effort limit)."""
        slot = self.slot[name]
        self.mode[slot] = TORQUE
        self.commanded_torque[slot] = min(max(value, -self.max_effort[slot]), self.max_effort[slot])

    def set_gains(self, name: str, kp: float, ki: float, kd: float) -> None:
        """Set the PID gains of joint `name`."""
        slot = self.slot[name]
        self.kp[slot], self.ki[slot], self.kd[slot] = kp, ki, kd
        self.integral[slot] = 0.0

    def apply(self) -> None:
        """Compute and send this step's torques."""
        # np.minimum/np.maximum rather than np.clip: the same numbers at half the call cost,
        # which matters 1,000 times per simulated second.
        self.read()
        error = self.target - self.position
        self.integral = np.minimum(
            np.maximum(self.integral + error * self.timestep, -INTEGRAL_LIMIT), INTEGRAL_LIMIT
        )
        pid = (
            self.kp * error
            + self.ki * self.integral
            + self.kd * (self.target_velocity - self.velocity)
        )
        torque = np.where(self.mode == POSITION, pid, self.commanded_torque)
        torque = np.minimum(np.maximum(torque, -self.max_effort), self.max_effort)
        # Velocity limit: past it, the actuator brakes with all it has, whatever was asked.
        over = np.abs(self.velocity) > self.max_velocity
        if over.any():
            torque = np.where(over, -np.sign(self.velocity) * self.max_effort, torque)
        self.applied = torque
        self.client.setJointMotorControlArray(
            self.robot, self.indices, pybullet.TORQUE_CONTROL, forces=torque.tolist()
        )

    def reset_to(self, posture: dict[str, float]) -> None:
        """Teleport every joint to `posture` (others to 0) at rest and hold it."""
        for slot, name in enumerate(self.names):
            value = min(max(posture.get(name, 0.0), self.lower[slot]), self.upper[slot])
            self.client.resetJointState(self.robot, self.indices[slot], value, 0.0)
            self.mode[slot] = POSITION
            self.target[slot] = value
        self.integral[:] = 0.0
        self.read()
