"""Robot sensors, each with a rate and Gaussian noise, computed only while subscribed."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drcsim._bullet import pybullet
from drcsim.control import JointController
from drcsim.models import humanoid
from drcsim.scene import Scene

SENSOR_TOPICS = ("joint_states", "imu", "lidar", "camera", "contact")
# The lidar's optical centre in the head frame (the one `head_in_pelvis` gives): above the
# stereo pair and ahead of the head's face, as the MultiSense SL carries its spinning Hokuyo;
# 8 cm ahead of the face, so beams starting 0.1 m out, up to 135° off forward, start outside it.
LIDAR_IN_HEAD = np.array([0.16, 0.0, 0.12])
LEFT_EYE_IN_HEAD = np.array([0.14, 0.035, 0.08])  # the stereo pair's left camera
STEREO_BASELINE = 0.07  # m: the right camera is this far right of the left one
NOISE_TABLE_SIZE = 1 << 16  # camera noise: one uint16 draw per channel indexes this table
# The ground plane's 1 m checker squares as TinyRenderer draws them (its default texture under
# its default light): the square whose corner (floor x, floor y) has an even sum, then an odd.
GROUND_RGBA = np.array([[162, 186, 239, 255], [239, 239, 239, 255]], dtype=np.uint8)
NEAR_M, FAR_M = 0.05, 50.0  # the camera's clipping planes
HORIZON_M = 1e4  # ground further along the view axis is within a pixel of the horizon: sky


def whole_level_noise(sigma: float) -> np.ndarray:
    """Return a table whose uniformly drawn entries are N(0, sigma) noise rounded to whole levels.

    Each level m fills as many of the 65,536 entries as N(0, sigma) puts between m - 1/2 and
    m + 1/2, so indexing it with uniform random uint16s draws the rounded Gaussian exactly (to
    1/65,536); that is four times as fast as drawing floats and rounding them for a 320x240 pair.
    """
    if sigma <= 0.0:
        return np.zeros(NOISE_TABLE_SIZE, dtype=np.int16)
    reach = math.ceil(6 * sigma)
    levels = np.arange(-reach, reach + 1)
    cdf = [0.5 * (1 + math.erf((m + 0.5) / (sigma * math.sqrt(2)))) for m in levels]
    ends = np.round(np.array(cdf) * NOISE_TABLE_SIZE).astype(np.int64)
    ends[-1] = NOISE_TABLE_SIZE
    return np.repeat(levels, np.diff(ends, prepend=0)).astype(np.int16)


@dataclass
class SensorSettings:
    """Rates (Hz), noise standard deviations and geometry of every sensor."""

    joint_states_hz: float = 100.0
    joint_position_noise: float = 0.0005
    imu_hz: float = 100.0
    gyro_noise: float = 0.002
    accel_noise: float = 0.02
    attitude_noise: float = 0.003  # rad, on each of roll, pitch, yaw of the orientation
    lidar_hz: float = 40.0
    lidar_beams: int = 1081
    lidar_fov: float = math.radians(270)
    lidar_range: float = 30.0
    lidar_min_range: float = 0.1  # the Hokuyo UTM-30LX's; beams start there, as Gazebo's did
    lidar_noise: float = 0.01
    lidar_spin: float = 0.5  # rad/s of the spindle
    camera_hz: float = 10.0
    camera_width: int = 320
    camera_height: int = 240
    camera_fov_deg: float = 80.0
    camera_noise: float = 2.0  # intensity levels (0..255)
    camera_stereo: bool = True  # the right image, 7 cm to the right of the left one
    contact_hz: float = 100.0
    contact_noise: float = 0.5  # newtons

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> SensorSettings:
        """Return settings with `values` overriding the defaults (unknown keys are an error)."""
        settings = cls()
        for key, value in values.items():
            if not hasattr(settings, key):
                raise KeyError(f"unknown sensor setting {key!r}")
            kind = type(getattr(settings, key))
            if kind is bool:
                setattr(settings, key, str(value).lower() in ("1", "true", "yes", "on"))
            else:
                setattr(settings, key, kind(value))
        settings.check()
        return settings

    def check(self) -> None:
        """Refuse settings no sensor can have (a ValueError naming the first)."""
        for key, value in vars(self).items():
            if isinstance(value, bool):
                continue
            may_be_zero = key.endswith(("noise", "spin"))
            if not math.isfinite(value) or value < 0 or (value == 0 and not may_be_zero):
                raise ValueError(f"{key} must be a finite number above 0 (noise and spin may be 0)")
        if self.lidar_min_range >= self.lidar_range:
            raise ValueError("lidar_min_range must be below lidar_range")


@dataclass
class Sensors:
    """Computes sensor messages on their schedule for the topics someone subscribes to."""

    scene: Scene
    controller: JointController
    settings: SensorSettings
    seed: int
    timestep: float
    rngs: dict[str, np.random.Generator] = field(default_factory=dict)
    last_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    last_imu_time: float = 0.0

    def __post_init__(self) -> None:
        # One generator per sensor: subscribing to one never shifts another's noise.
        self.rngs = {
            topic: np.random.default_rng([self.seed, index])
            for index, topic in enumerate(SENSOR_TOPICS)
        }
        self.period = {
            topic: max(1, round(1.0 / (self.timestep * getattr(self.settings, f"{topic}_hz"))))
            for topic in SENSOR_TOPICS
        }
        s = self.settings
        self.projection = self.scene.client.computeProjectionMatrixFOV(
            s.camera_fov_deg, s.camera_width / s.camera_height, NEAR_M, FAR_M
        )
        # Each pixel centre's ray in the camera frame, per unit of depth along the view axis:
        # `right` times the column's slope plus `up` times the row's, plus the view axis.
        slope = math.tan(math.radians(s.camera_fov_deg) / 2)
        columns = (np.arange(s.camera_width) + 0.5) * 2 / s.camera_width - 1
        rows = 1 - (np.arange(s.camera_height) + 0.5) * 2 / s.camera_height
        self.ray_right = (columns * slope * s.camera_width / s.camera_height).astype(np.float32)
        self.ray_up = (rows[:, np.newaxis] * slope).astype(np.float32)
        # TinyRenderer's depth buffer d gives 1 / depth = 1 / near - d (far - near) / (far near)
        self.inverse_near = np.float32(1.0 / NEAR_M)
        self.inverse_depth_scale = np.float32((FAR_M - NEAR_M) / (FAR_M * NEAR_M))
        self.inverse_sky = np.float32(1.0 / (0.999 * FAR_M))  # at the far plane: nothing drawn
        ground_rgba = self.scene.client.getVisualShapeData(self.scene.ground)[0][7]
        self.ground_rgba = list(ground_rgba)
        self.ground_hidden = [*ground_rgba[:3], 0.0]
        self.ground_pixels = GROUND_RGBA.view(np.uint32).ravel()
        self.camera_noise = whole_level_noise(s.camera_noise)
        self.lidar_angles = np.linspace(-s.lidar_fov / 2, s.lidar_fov / 2, s.lidar_beams)

    def due(self, step: int, active: set[str]) -> list[str]:
        """Return the subscribed sensor topics due at physics step `step`."""
        return [t for t in SENSOR_TOPICS if t in active and step % self.period[t] == 0]

    def compute(self, topic: str, sim_time: float) -> dict[str, Any]:
        """Return one message of sensor `topic`."""
        message: dict[str, Any] = getattr(self, f"_{topic}")(self.rngs[topic], sim_time)
        message["t"] = round(sim_time, 6)
        return message

    def _joint_states(self, rng: np.random.Generator, _: float) -> dict[str, Any]:
        c = self.controller
        noise = rng.normal(0.0, self.settings.joint_position_noise, len(c.names))
        return {
            "name": c.names,
            "position": (c.position + noise).tolist(),
            "velocity": c.velocity.tolist(),
            "effort": c.applied.tolist(),
        }

    def _imu(self, rng: np.random.Generator, sim_time: float) -> dict[str, Any]:
        client, robot = self.scene.client, self.scene.robot
        _, orn = client.getBasePositionAndOrientation(robot)
        linear, angular = client.getBaseVelocity(robot)
        dt = max(sim_time - self.last_imu_time, self.timestep)
        accel_world = [(v - w) / dt for v, w in zip(linear, self.last_velocity, strict=True)]
        accel_world[2] += 9.81  # an accelerometer at rest reads +g
        self.last_velocity, self.last_imu_time = tuple(linear), sim_time
        _, inverse = client.invertTransform([0, 0, 0], orn)
        rotate = np.array(client.getMatrixFromQuaternion(inverse)).reshape(3, 3)
        gyro = rotate @ np.array(angular) + rng.normal(0, self.settings.gyro_noise, 3)
        accel = rotate @ np.array(accel_world) + rng.normal(0, self.settings.accel_noise, 3)
        roll, pitch, yaw = client.getEulerFromQuaternion(orn)
        tilt = rng.normal(0.0, self.settings.attitude_noise, 3)
        return {
            "orientation": list(
                client.getQuaternionFromEuler([roll + tilt[0], pitch + tilt[1], yaw + tilt[2]])
            ),
            "angular_velocity": gyro.tolist(),
            "linear_acceleration": accel.tolist(),
        }

    def _head_pose(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.scene.client.getLinkState(
            self.scene.robot, self.scene.robot_links[humanoid.HEAD_LINK]
        )
        rotation = np.array(self.scene.client.getMatrixFromQuaternion(state[1])).reshape(3, 3)
        return np.array(state[0]), rotation

    def _head_in_pelvis(self) -> dict[str, list[float]]:
        """Return the head frame in the pelvis frame (kinematics the robot knows, like tf)."""
        client, robot = self.scene.client, self.scene.robot
        head = client.getLinkState(robot, self.scene.robot_links[humanoid.HEAD_LINK])
        base_pos, base_orn = client.getBasePositionAndOrientation(robot)
        inv_pos, inv_orn = client.invertTransform(base_pos, base_orn)
        pos, orn = client.multiplyTransforms(inv_pos, inv_orn, head[0], head[1])
        return {"position": list(pos), "orientation": list(orn)}

    def _lidar_rays(self, spindle: float) -> tuple[np.ndarray, np.ndarray]:
        """Return the beams' start and end points for the spindle angle `spindle`."""
        s = self.settings
        origin, rotation = self._head_pose()
        angles = self.lidar_angles
        # Scan plane: the head's x-y plane rolled about the head x axis by the spindle angle.
        local = np.stack(
            [
                np.cos(angles),
                np.sin(angles) * math.cos(spindle),
                np.sin(angles) * math.sin(spindle),
            ],
            axis=1,
        )
        directions = local @ rotation.T
        sensor = origin + rotation @ LIDAR_IN_HEAD
        # Like the real sensor (nothing nearer than its minimum range) and Gazebo's ray
        # sensor in the VRC, each beam starts at the minimum range: never inside the head.
        starts = sensor + directions * s.lidar_min_range
        return starts, sensor + directions * s.lidar_range

    def _lidar(self, rng: np.random.Generator, sim_time: float) -> dict[str, Any]:
        s = self.settings
        spindle = (s.lidar_spin * sim_time) % (2 * math.pi)
        starts, ends = self._lidar_rays(spindle)
        # The arrays as they are: pybullet reads the same doubles as from lists, without them.
        hits = self.scene.client.rayTestBatch(starts, ends)
        span = s.lidar_range - s.lidar_min_range
        ranges = s.lidar_min_range + np.array([h[2] for h in hits]) * span
        ranges = ranges + rng.normal(0.0, s.lidar_noise, s.lidar_beams)
        ranges = np.clip(ranges, s.lidar_min_range, s.lidar_range).astype(np.float32)
        return {
            "angle_min": -s.lidar_fov / 2,
            "angle_max": s.lidar_fov / 2,
            "spindle": spindle,
            "range_min": s.lidar_min_range,
            "range_max": s.lidar_range,
            "ranges": ranges.tobytes(),
            "head_in_pelvis": self._head_in_pelvis(),
        }

    def _render(self, eye: np.ndarray, rotation: np.ndarray, rng: np.random.Generator) -> bytes:
        s = self.settings
        forward, up = rotation[:, 0], rotation[:, 2]
        client, ground = self.scene.client, self.scene.ground
        view = client.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), up.tolist())
        # TinyRenderer draws every body but the ground plane, which costs it two thirds of an
        # image (~250 ns per pixel it covers); `_ground` then draws the plane exactly where
        # it is nearer than what TinyRenderer drew, as its depth test would have.
        client.changeVisualShape(ground, -1, rgbaColor=self.ground_hidden)
        try:
            _, _, rgba, depth, _ = client.getCameraImage(
                s.camera_width,
                s.camera_height,
                view,
                self.projection,
                renderer=pybullet.ER_TINY_RENDERER,
                flags=pybullet.ER_NO_SEGMENTATION_MASK,  # not published: skip computing it
            )
        finally:
            client.changeVisualShape(ground, -1, rgbaColor=self.ground_rgba)
        shape = (s.camera_height, s.camera_width)
        image = np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (*shape, 4)))
        self._ground(image.view(np.uint32).reshape(shape), np.reshape(depth, shape), eye, rotation)
        noisy = image[:, :, :3].astype(np.int16)
        draws = np.frombuffer(rng.bytes(2 * noisy.size), dtype=np.uint16)
        noisy += np.take(self.camera_noise, draws).reshape(noisy.shape)
        np.clip(noisy, 0, 255, out=noisy)
        return noisy.astype(np.uint8).tobytes()

    def _ground(
        self, pixels: np.ndarray, depth: np.ndarray, eye: np.ndarray, rotation: np.ndarray
    ) -> None:
        """Draw the ground plane (z = 0) into `pixels` (RGBA, one uint32 each) where nearest.

        Each pixel centre's ray meets the plane at a depth `t` along the view axis; the plane
        shows where that is nearer than TinyRenderer's depth there (or where it drew nothing:
        the plane reaches the horizon, as TinyRenderer drew it), in its checker squares.
        Compared as 1 / depth, which both the ray and TinyRenderer's depth buffer give linearly.
        """
        f32 = np.float32
        forward, right, up = rotation[:, 0], -rotation[:, 1], rotation[:, 2]

        def ray(axis: int) -> np.ndarray:  # each pixel's ray, per unit of depth, along `axis`
            along = self.ray_right * f32(right[axis]) + f32(forward[axis])
            return along + self.ray_up * f32(up[axis])

        inverse_t = ray(2) * f32(-1.0 / eye[2]) if eye[2] != 0 else np.zeros_like(depth)
        inverse_drawn = self.inverse_near - self.inverse_depth_scale * depth
        inverse_drawn[inverse_drawn < self.inverse_sky] = f32(1.0 / HORIZON_M)  # nothing drawn
        show = inverse_t > inverse_drawn
        t = f32(1.0) / np.maximum(inverse_t, f32(1.0 / HORIZON_M))
        x, y = ray(0) * t + f32(eye[0]), ray(1) * t + f32(eye[1])
        odd = (np.floor(x) + np.floor(y)).astype(np.int32) & 1
        np.copyto(pixels, self.ground_pixels[odd], where=show)

    def _camera(self, rng: np.random.Generator, _: float) -> dict[str, Any]:
        s = self.settings
        origin, rotation = self._head_pose()
        left = origin + rotation @ LEFT_EYE_IN_HEAD
        message: dict[str, Any] = {
            "width": s.camera_width,
            "height": s.camera_height,
            "encoding": "rgb8",
            "data": self._render(left, rotation, rng),
            "head_in_pelvis": self._head_in_pelvis(),
        }
        if s.camera_stereo:
            right = left - rotation[:, 1] * STEREO_BASELINE
            message["right"] = self._render(right, rotation, rng)
        return message

    def _contact(self, rng: np.random.Generator, _: float) -> dict[str, Any]:
        client, scene = self.scene.client, self.scene
        forces: dict[str, float] = {}
        for hand in ("left", "right"):
            total = 0.0
            for link_name in (humanoid.HAND_LINKS[hand], humanoid.FINGER_LINKS[hand]):
                link = scene.robot_links[link_name]
                total += sum(
                    p[9] for p in client.getContactPoints(bodyA=scene.robot, linkIndexA=link)
                )
            forces[hand] = max(0.0, total + float(rng.normal(0.0, self.settings.contact_noise)))
        return {"force": forces}
