"""What a run writes into its MCAP log: the world once, body poses, what the team received,
score events and commands (the topics are listed in drcsim.mcaplog.TOPICS)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drcsim._bullet import BulletClient
from drcsim.mcaplog import (
    INFO,
    KEY_FRAME_S,
    TOPICS,
    WARNING,
    WORLD_FRAME,
    McapWriter,
    TransformEncoder,
    compressed_image,
    estimate_pose,
    pose,
    stamp,
)
from drcsim.sensors import LIDAR_IN_HEAD
from drcsim.viewer import describe_scene, moving_bodies

TICK_HZ = 100  # the simulation's ticks (scene.TICK_STEPS physics steps)
GROUND_SIZE = 200.0  # m: the side of the square that stands for the infinite ground plane
PELVIS_FRAME = "robot/pelvis"  # the robot's base link frame (where its sensors hang from)
HEAD_FRAME = "robot/head"
# The fields of a team topic's message that its MCAP topic keeps (lidar and camera convert).
TEAM_FIELDS = {
    "joint_states": ("name", "position", "velocity", "effort"),
    "imu": ("orientation", "angular_velocity", "linear_acceleration"),
    "contact": ("force",),
    "robot_state": ("step", "pelvis", "joints", "behaviour", "score"),
}  # the frame the lidar and camera give their readings in


def frame_names(scene: dict[str, Any], roles: dict[str, Any]) -> dict[int, list[str]]:
    """Return each body's link frame names ("robot/pelvis", "vehicle/steering_wheel", ...)."""
    named = {
        body: role for role, body in roles.items() if isinstance(body, int) and role != "robot_link"
    }
    names: dict[int, list[str]] = {}
    seen: set[str] = set()
    for entry in scene["bodies"]:
        body = entry["id"]
        base = named.get(body) or entry["name"] or f"body{body}"
        if base in seen:  # many bodies share a URDF name (rubble blocks)
            base = f"{base}_{body}"
        seen.add(base)
        names[body] = [f"{base}/{link}" for link in entry["links"]]
    return names


def scene_update(scene: dict[str, Any], frames: dict[int, list[str]]) -> dict[str, Any]:
    """Return the world's shapes as a foxglove.SceneUpdate, one entity per body link.

    Moving bodies' entities hang off their link frames (so /tf moves them); static bodies'
    are placed in the world frame once. Capsules become a cylinder between two spheres;
    meshes are left out (Foxglove's primitives have no mesh the file could carry).
    """
    entities = []
    for entry in scene["bodies"]:
        names = frames[entry["id"]]
        static = entry.get("poses")
        by_link: dict[int, list[dict[str, Any]]] = {}
        for shape in entry["shapes"]:
            by_link.setdefault(shape["link"], []).append(shape)
        for link, shapes in sorted(by_link.items()):
            primitives: dict[str, list[dict[str, Any]]] = {
                "cubes": [],
                "spheres": [],
                "cylinders": [],
            }
            for shape in shapes:
                _primitives(shape, primitives)
            entity_frame = names[link] if static is None else WORLD_FRAME
            if static is not None:
                link_pose = static[7 * link : 7 * link + 7]
                for kind in primitives.values():
                    for primitive in kind:
                        primitive["pose"] = _compose(link_pose, primitive["pose"])
            entities.append(
                {
                    "timestamp": stamp(0.0),
                    "frame_id": entity_frame,
                    "id": names[link],
                    "lifetime": {"sec": 0, "nsec": 0},  # forever
                    "frame_locked": static is None,
                    "metadata": [{"key": "body", "value": str(entry["id"])}],
                    **primitives,
                    "arrows": [],
                    "lines": [],
                    "triangles": [],
                    "texts": [],
                    "models": [],
                }
            )
    return {"deletions": [], "entities": entities}


def _primitives(shape: dict[str, Any], into: dict[str, list[dict[str, Any]]]) -> None:
    r, g, b, a = shape["rgba"]
    color = {"r": r, "g": g, "b": b, "a": a}
    at = pose(shape["xyz"], shape["quat"])
    kind = shape["type"]
    if kind == "box":
        x, y, z = shape["size"]  # pybullet gives half extents
        into["cubes"].append(
            {"pose": at, "size": {"x": 2 * x, "y": 2 * y, "z": 2 * z}, "color": color}
        )
    elif kind == "plane":
        size = {"x": GROUND_SIZE, "y": GROUND_SIZE, "z": 0.001}
        into["cubes"].append({"pose": at, "size": size, "color": color})
    elif kind == "sphere":
        d = 2 * shape["radius"]
        into["spheres"].append({"pose": at, "size": {"x": d, "y": d, "z": d}, "color": color})
    elif kind in ("cylinder", "capsule"):
        d, length = 2 * shape["radius"], shape["length"]
        size = {"x": d, "y": d, "z": length}
        into["cylinders"].append(
            {"pose": at, "size": size, "bottom_scale": 1.0, "top_scale": 1.0, "color": color}
        )
        if kind == "capsule":
            for end in (-0.5, 0.5):
                offset = _rotate(shape["quat"], [0.0, 0.0, end * length])
                centre = [c + o for c, o in zip(shape["xyz"], offset, strict=True)]
                ball = {"pose": pose(centre, shape["quat"]), "size": {"x": d, "y": d, "z": d}}
                into["spheres"].append({**ball, "color": color})


def _rotate(quat: Sequence[float], vector: Sequence[float]) -> list[float]:
    x, y, z, w = quat
    u = np.array([x, y, z])
    v = np.array(vector, dtype=float)
    rotated = 2 * np.dot(u, v) * u + (w * w - np.dot(u, u)) * v + 2 * w * np.cross(u, v)
    return [float(c) for c in rotated]


def _quat_multiply(a: Sequence[float], b: Sequence[float]) -> list[float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ]


def _compose(link: Sequence[float], local: dict[str, Any]) -> dict[str, Any]:
    """Return a shape's pose in the world from its link's world pose and its pose in the link."""
    p, o = local["position"], local["orientation"]
    offset = _rotate(link[3:7], [p["x"], p["y"], p["z"]])
    position = [float(link[i]) + offset[i] for i in range(3)]
    return pose(position, _quat_multiply(link[3:7], [o["x"], o["y"], o["z"], o["w"]]))


class LinkPoses:
    """Reads every link frame's world pose of some bodies, as `viewer.link_poses` does but
    without its forward kinematics (which would change the next physics step, so a replay
    would diverge from the recorded run) and about six times as fast."""

    def __init__(self, client: BulletClient, bodies: Sequence[int]) -> None:
        self.client = client
        self.plan = []
        for body in bodies:
            info = client.getDynamicsInfo(body, -1)
            inverse = client.invertTransform(info[3], info[4])
            offset, turn = inverse
            identity = all(abs(v) < 1e-12 for v in offset) and abs(abs(turn[3]) - 1) < 1e-12
            links = list(range(client.getNumJoints(body)))
            self.plan.append((body, None if identity else inverse, links))

    def read(self) -> list[float]:
        """Return the poses, x, y, z, qx, qy, qz, qw a frame, each body's base first."""
        client, flat = self.client, []
        for body, inverse, links in self.plan:
            xyz, quat = client.getBasePositionAndOrientation(body)
            if inverse is not None:  # the base's URDF frame, not its inertial frame
                xyz, quat = client.multiplyTransforms(xyz, quat, *inverse)
            flat.extend(xyz)
            flat.extend(quat)
            if links:
                for state in client.getLinkStates(body, links):
                    flat.extend(state[4])
                    flat.extend(state[5])
        return flat


class RunRecorder:
    """Writes one run's MCAP log as the simulation goes."""

    def __init__(
        self,
        path: Path,
        client: BulletClient,
        roles: dict[str, Any],
        meta: dict[str, Any],
        pose_every_ticks: int = 1,
    ) -> None:
        self.client = client
        self.writer = McapWriter(path, {"drcsim.run": {k: str(v) for k, v in meta.items()}})
        scene = describe_scene(client, roles)
        names = frame_names(scene, roles)
        self.bodies = moving_bodies(client)
        self.frames = [name for body in self.bodies for name in names[body]]
        self.pose_every_ticks = max(1, pose_every_ticks)
        self.key_every_ticks = self.pose_every_ticks * max(
            1, round(KEY_FRAME_S * TICK_HZ / self.pose_every_ticks)
        )
        self.encoder = TransformEncoder(self.frames)
        self.poses = LinkPoses(client, self.bodies)
        self.writer.message("/world/scene", 0.0, scene_update(scene, names))
        self.ticks = 0

    def tick(self, sim_time: float, estimate: dict[str, list[float]]) -> None:
        """Record the 100 Hz tick: the moving links' poses (at their rate) and the estimate."""
        if self.ticks % self.pose_every_ticks == 0:
            flat = self.poses.read()
            # every frame at each whole second (the first message has them all anyway)
            key = round(sim_time * TICK_HZ) % self.key_every_ticks == 0
            poses = self.encoder.encode(sim_time, flat, key)
            self.writer.write("/tf", TOPICS["/tf"], sim_time, poses)
            data = estimate_pose(sim_time, estimate["position"], estimate["orientation"])
            self.writer.write("/robot/estimate", TOPICS["/robot/estimate"], sim_time, data)
        self.ticks += 1

    def team(self, topic: str, sim_time: float, message: dict[str, Any]) -> None:
        """Record a message the team was sent on a LAN topic, as it was sent."""
        fields = TEAM_FIELDS.get(topic)
        if fields is not None:
            record = {"timestamp": stamp(sim_time), **{key: message[key] for key in fields}}
            self.writer.message(f"/team/{topic}", sim_time, record)
        if topic == "lidar":
            self._lidar(sim_time, message)
        elif topic == "camera":
            self._camera(sim_time, message)

    def _lidar(self, sim_time: float, message: dict[str, Any]) -> None:
        ranges = np.frombuffer(message["ranges"], dtype=np.float32)
        # the scan plane is the head's x-y plane rolled by the spindle angle about head x
        half = float(message["spindle"]) / 2
        scan = {
            "timestamp": stamp(sim_time),
            "frame_id": HEAD_FRAME,
            "pose": pose(LIDAR_IN_HEAD.tolist(), [np.sin(half), 0.0, 0.0, np.cos(half)]),
            "start_angle": float(message["angle_min"]),
            "end_angle": float(message["angle_max"]),
            "ranges": np.round(ranges.astype(np.float64), 3).tolist(),
            "intensities": [],
        }
        self.writer.message("/team/lidar", sim_time, scan)

    def _camera(self, sim_time: float, message: dict[str, Any]) -> None:
        size = (int(message["width"]), int(message["height"]))
        for side, key in (("left", "data"), ("right", "right")):
            if key in message:
                image = compressed_image(sim_time, HEAD_FRAME, *size, message[key])
                self.writer.message(f"/team/camera/{side}", sim_time, image)

    def score(self, event: dict[str, Any]) -> None:
        """Record a score log event as a foxglove.Log and as itself."""
        sim_time = float(event["sim_time"])
        kind = event.get("event")
        if kind == "checkpoint":
            text, level = (
                f"checkpoint {event.get('checkpoint')} reached: {event.get('name', '')}",
                INFO,
            )
        elif kind == "fall":
            text, level = f"fall {event.get('falls', '')}", WARNING
        elif kind == "run_end":
            text, level = (
                f"run ended: {event.get('reason', '')} (score {event.get('score', 0)})",
                INFO,
            )
        else:
            text, level = str(kind), INFO
        log = {
            "timestamp": stamp(sim_time),
            "level": level,
            "message": text.strip(),
            "name": "drcsim.scoring",
            "file": "",
            "line": 0,
        }
        self.writer.message("/score", sim_time, log)
        self.writer.message(
            "/score/events", sim_time, {"timestamp": stamp(sim_time), "event": event}
        )

    def command(self, sim_time: float, step: int, message: dict[str, Any], source: str) -> None:
        """Record a command the simulator applied before step `step`, with its sender."""
        record = {"timestamp": stamp(sim_time), "step": step, "source": source, "command": message}
        self.writer.message("/commands", sim_time, record)

    def close(self, final: dict[str, Any]) -> None:
        """Finish the file with the run's final record as metadata."""
        self.writer.close({"drcsim.final": {k: json.dumps(v) for k, v in final.items()}})
