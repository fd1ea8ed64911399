"""The vehicle's drive-by-wire: wheels respond only to the positions of the human interfaces."""

from __future__ import annotations

import math

from drcsim._bullet import BulletClient, pybullet
from drcsim.models.vehicle import (
    BRAKE_TORQUE,
    DRIVE_TORQUE,
    DRIVEN_WHEELS,
    HAND_BRAKE_TORQUE,
    INTERFACES,
    MAX_SPEED,
    MAX_STEER,
    PEDALS,
    STEER_JOINTS,
    STEERING_RATIO,
    WHEEL_RADIUS,
    WHEELS,
)

ROLLING_RESISTANCE = 5.0  # N m per wheel
PEDAL_SPRING = 10.0  # N m/rad: the pedals' return springs
PEDAL_PRELOAD = 1.5  # N m holding a released pedal up
DIRECTIONS = {"forward": 0.3, "neutral": 0.0, "reverse": -0.3}


class VehicleDrive:
    """Springs the pedals back and turns the wheels from the interfaces' positions."""

    def __init__(self, client: BulletClient, body: int, joints: dict[str, int]) -> None:
        self.client = client
        self.body = body
        self.joints = joints
        # The pedals are sprung: only a foot pressing on them moves them.
        client.setJointMotorControlArray(
            body, [joints[n] for n in PEDALS], pybullet.VELOCITY_CONTROL, forces=[0.0, 0.0]
        )

    def interface_positions(self) -> dict[str, float]:
        """Return where each interface actually is."""
        indices = [self.joints[name] for name in INTERFACES]
        states = self.client.getJointStates(self.body, indices)
        return {name: state[0] for name, state in zip(INTERFACES, states, strict=True)}

    def apply(self) -> None:
        """Spring the pedals back and drive the wheels from where the interfaces are."""
        pos = self.interface_positions()
        for pedal in PEDALS:
            self.client.setJointMotorControl2(
                self.body,
                self.joints[pedal],
                pybullet.TORQUE_CONTROL,
                force=-(PEDAL_SPRING * pos[pedal] + PEDAL_PRELOAD),
            )
        throttle = pos["throttle_pedal"] / INTERFACES["throttle_pedal"].upper
        brake = pos["brake_pedal"] / INTERFACES["brake_pedal"].upper
        hand_brake = pos["hand_brake"] > 0.5 * INTERFACES["hand_brake"].upper
        fnr = pos["fnr_switch"]
        direction = 1.0 if fnr > 0.15 else -1.0 if fnr < -0.15 else 0.0
        brake_torque = max(brake, 0.0) * BRAKE_TORQUE + (HAND_BRAKE_TORQUE if hand_brake else 0)
        steer = min(max(pos["steering_wheel"] / STEERING_RATIO, -MAX_STEER), MAX_STEER)
        self.client.setJointMotorControlArray(
            self.body,
            [self.joints[n] for n in STEER_JOINTS],
            pybullet.POSITION_CONTROL,
            targetPositions=[steer, steer],
            forces=[2000.0, 2000.0],
        )
        for wheel in WHEELS:
            index = self.joints[wheel]
            if brake_torque > 1.0:
                velocity, force = 0.0, brake_torque
            elif wheel in DRIVEN_WHEELS and direction != 0.0 and throttle > 0.02:
                velocity = direction * throttle * MAX_SPEED / WHEEL_RADIUS
                force = DRIVE_TORQUE * throttle
            else:
                velocity, force = 0.0, ROLLING_RESISTANCE
            self.client.setJointMotorControl2(
                self.body, index, pybullet.VELOCITY_CONTROL, targetVelocity=velocity, force=force
            )

    def speed(self) -> float:
        """Return the chassis's horizontal speed (m/s)."""
        linear, _ = self.client.getBaseVelocity(self.body)
        return math.hypot(linear[0], linear[1])
