"""The robot's own state estimate: what `state` reports, from noisy sensors, never ground truth.

Orientation comes from the IMU (small noise, a slowly drifting yaw), position from leg and
vehicle odometry (a per-run scale error plus a random walk), joints from the encoders (noise).
It runs at 100 Hz whether or not anyone asks, with its own seeded generator, so that reading
`state` never changes anything and runs stay bitwise reproducible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drcsim._bullet import BulletClient
from drcsim.control import JointController


@dataclass(frozen=True)
class EstimatorNoise:
    """Standard deviations of the estimator's errors."""

    attitude: float = 0.003  # rad, roll/pitch/yaw noise per estimate
    yaw_drift: float = 0.0004  # rad per 100 Hz tick, random walk
    odometry_scale: float = 0.02  # relative error of travelled distance, fixed per run
    position_walk: float = 0.0006  # m per 100 Hz tick while moving, random walk
    joint_position: float = 0.0005  # rad
    joint_velocity: float = 0.01  # rad/s


def _quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]


class Estimator:
    """Dead-reckons the pelvis pose and filters nothing: noise in, noise out, like a robot."""

    def __init__(
        self,
        client: BulletClient,
        robot: int,
        controller: JointController,
        seed: int,
        noise: EstimatorNoise | None = None,
    ) -> None:
        self.client, self.robot, self.controller = client, robot, controller
        self.noise = noise or EstimatorNoise()
        self.rng = np.random.default_rng([seed, 977])
        self.scale = 1.0 + float(self.rng.normal(0.0, self.noise.odometry_scale))
        pos, _ = client.getBasePositionAndOrientation(robot)
        self.true_last = np.array(pos, dtype=float)
        # The start pose is known (the robot is placed there): the estimate starts exact.
        self.position = np.array(pos, dtype=float)
        self.yaw_error = 0.0
        self.orientation: list[float] = list(client.getBasePositionAndOrientation(robot)[1])
        self.joint_position = controller.position.copy()
        self.joint_velocity = controller.velocity.copy()

    def update(self) -> None:
        """Fold this tick's sensor readings into the estimate (100 Hz)."""
        n, rng = self.noise, self.rng
        pos, orn = self.client.getBasePositionAndOrientation(self.robot)
        true = np.array(pos, dtype=float)
        moved = true - self.true_last
        self.true_last = true
        self.yaw_error += float(rng.normal(0.0, n.yaw_drift))
        c, s = math.cos(self.yaw_error), math.sin(self.yaw_error)
        step = self.scale * np.array([c * moved[0] - s * moved[1], s * moved[0] + c * moved[1]])
        walk = rng.normal(0.0, n.position_walk, 2) * min(1.0, float(np.linalg.norm(moved)) * 100)
        self.position[:2] += step + walk
        self.position[2] = true[2] + float(rng.normal(0.0, 0.002))
        roll, pitch, yaw = self.client.getEulerFromQuaternion(orn)
        jitter = rng.normal(0.0, n.attitude, 3)
        self.orientation = _quaternion(
            roll + jitter[0], pitch + jitter[1], yaw + self.yaw_error + jitter[2]
        )
        c_ = self.controller
        self.joint_position = c_.position + rng.normal(0.0, n.joint_position, len(c_.names))
        self.joint_velocity = c_.velocity + rng.normal(0.0, n.joint_velocity, len(c_.names))

    def pelvis(self) -> dict[str, list[float]]:
        """Return the estimated pelvis pose."""
        return {"position": self.position.tolist(), "orientation": list(self.orientation)}
