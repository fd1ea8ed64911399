"""What a 3D viewer needs: every body's shapes once, then link poses per frame.

Generic over whatever the world holds: it reads pybullet's visual (or, lacking one, collision)
shape data of every body, so new bodies, links or terrain appear without changes here.
Poses are URDF link frames (the frames the shapes are given in), position + quaternion (x, y,
z, w), in metres, world coordinates, z up.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drcsim._bullet import BulletClient, pybullet
from drcsim.scene import TICK_STEPS

FORMAT = 1
POSE_DECIMALS = 6  # micrometres: far below what a viewer (or a 1 mm comparison) resolves
GEOMETRY = {
    pybullet.GEOM_SPHERE: "sphere",
    pybullet.GEOM_BOX: "box",
    pybullet.GEOM_CYLINDER: "cylinder",
    pybullet.GEOM_CAPSULE: "capsule",
    pybullet.GEOM_PLANE: "plane",
    pybullet.GEOM_MESH: "mesh",
}
Pose = tuple[Sequence[float], Sequence[float]]


def _is_moving(client: BulletClient, body: int) -> bool:
    """Return whether a body can move: it has mass or a joint that is not fixed."""
    if client.getDynamicsInfo(body, -1)[0] > 0:
        return True
    return any(
        client.getJointInfo(body, j)[2] != pybullet.JOINT_FIXED
        for j in range(client.getNumJoints(body))
    )


def _shape(client: BulletClient, record: Sequence[Any], visual: bool) -> dict[str, Any] | None:
    """Return one shape as plain data, its frame relative to its URDF link frame."""
    kind = GEOMETRY.get(record[2])
    if kind is None:
        return None
    body, link, dims = record[0], record[1], record[3]
    xyz, quat = record[5], record[6]
    if not visual:
        # collision frames are given relative to the link's inertial frame
        inertial = _inertial_frame(client, body, link)
        xyz, quat = client.multiplyTransforms(inertial[0], inertial[1], xyz, quat)
    shape: dict[str, Any] = {
        "link": link + 1,
        "type": kind,
        "xyz": _rounded(xyz),
        "quat": _rounded(quat),
        "rgba": _rounded(record[7]) if visual else [0.55, 0.6, 0.55, 1.0],
    }
    if kind == "box":
        shape["size"] = _rounded(dims[:3])
    elif kind == "sphere":
        shape["radius"] = round(float(dims[0]), POSE_DECIMALS)
    elif kind in ("cylinder", "capsule"):
        shape["length"], shape["radius"] = (round(float(d), POSE_DECIMALS) for d in dims[:2])
    elif kind == "mesh":
        shape["scale"] = _rounded(dims[:3])
    return shape


def _inertial_frame(client: BulletClient, body: int, link: int) -> Pose:
    info = client.getDynamicsInfo(body, link)
    return info[3], info[4]


def _rounded(values: Sequence[float]) -> list[float]:
    return [round(float(v), POSE_DECIMALS) for v in values]


def link_poses(client: BulletClient, body: int, kinematics: bool = True) -> list[float]:
    """Return the world pose of every link frame of a body (base first), flattened by 7.

    Without `kinematics` the links are where the last physics step left them rather than
    recomputed from the joints: pybullet's forward kinematics changes what the next step
    computes, so a run's own recording must not ask for it (replays would diverge).
    """
    base_xyz, base_quat = client.getBasePositionAndOrientation(body)
    # the base pose pybullet reports is its inertial frame; shapes hang off the URDF frame
    inverse = client.invertTransform(*_inertial_frame(client, body, -1))
    xyz, quat = client.multiplyTransforms(base_xyz, base_quat, *inverse)
    flat = [*xyz, *quat]
    count = client.getNumJoints(body)
    if count:
        states = client.getLinkStates(body, range(count), computeForwardKinematics=kinematics)
        for state in states:
            flat.extend([*state[4], *state[5]])
    return _rounded(flat)


def describe_scene(client: BulletClient, roles: dict[str, Any] | None = None) -> dict[str, Any]:
    """Return every body's shapes, link names, whether it moves, and static bodies' poses."""
    bodies = []
    for index in range(client.getNumBodies()):
        body = client.getBodyUniqueId(index)
        base_name, body_name = (name.decode() for name in client.getBodyInfo(body))
        links = [base_name] + [
            client.getJointInfo(body, j)[12].decode() for j in range(client.getNumJoints(body))
        ]
        records = client.getVisualShapeData(body)
        visual = bool(records)
        if not visual:
            records = [
                record
                for link in range(-1, len(links) - 1)
                for record in client.getCollisionShapeData(body, link)
            ]
        shapes = [s for s in (_shape(client, r, visual) for r in records) if s is not None]
        moving = _is_moving(client, body)
        entry: dict[str, Any] = {
            "id": body,
            "name": body_name or base_name,
            "links": links,
            "moving": moving,
            "shapes": shapes,
        }
        if not moving:
            entry["poses"] = link_poses(client, body)
        bodies.append(entry)
    return {"format": FORMAT, "bodies": bodies, "roles": roles or {}}


def pose_frame(client: BulletClient, bodies: Sequence[int], t: float, step: int) -> dict[str, Any]:
    """Return one frame: the link poses of the given (moving) bodies at simulated time t."""
    return {
        "t": round(t, 6),
        "step": step,
        "poses": {str(body): link_poses(client, body) for body in bodies},
    }


def moving_bodies(client: BulletClient) -> list[int]:
    """Return the ids of every body that can move (the ones a frame carries)."""
    ids = [client.getBodyUniqueId(i) for i in range(client.getNumBodies())]
    return [body for body in ids if _is_moving(client, body)]


@dataclass
class PoseStream:
    """Frames of a world at a given rate of simulated time (the `poses` topic's schedule)."""

    client: BulletClient
    rate_hz: float = 30.0

    def __post_init__(self) -> None:
        self.bodies = moving_bodies(self.client)

    def every_steps(self, timestep: float) -> int:
        """Return how many physics steps lie between two frames."""
        return max(1, round(1.0 / (self.rate_hz * timestep)))

    def frame(self, t: float, step: int) -> dict[str, Any]:
        """Return the frame for now."""
        return pose_frame(self.client, self.bodies, t, step)


class StateLogPoses:
    """Link poses of a logged run rebuilt from its state log, without stepping physics.

    The state log holds, for each moving body, its base pose and every joint position
    (float32); forward kinematics on a freshly built world gives every link's pose.
    """

    def __init__(self, log_dir: Path) -> None:
        from drcsim.engine import RunOptions, Simulation
        from drcsim.rundir import WORLD, read_meta
        from drcsim.worlds import read_world_file

        meta = read_meta(log_dir)
        self.log_dir = log_dir
        handed = log_dir / WORLD  # the world the run was built from, if it was handed over
        options = RunOptions(
            time_limit_s=meta["time_limit_s"],
            world_document=read_world_file(handed) if handed.exists() else None,
        )
        self.sim = Simulation(meta["world"], meta["config"], options)
        self.client = self.sim.client
        self.bodies = self.sim.state_bodies()
        self._marks: set[tuple[float, int]] = set()  # (t, byte offset) of whole seconds

    def scene(self) -> dict[str, Any]:
        """Return the world's description (as `describe_scene`), with the robot's roles."""
        return describe_scene(self.client, scene_roles(self.sim))

    def apply(self, values: Sequence[float]) -> None:
        """Put every logged body where a state vector says (the layout of `state_vector`)."""
        client, at = self.client, 0
        for body in self.bodies:
            client.resetBasePositionAndOrientation(
                body, values[at : at + 3], values[at + 3 : at + 7]
            )
            at += 13  # position, orientation, linear and angular velocity
            for joint in range(client.getNumJoints(body)):
                client.resetJointState(body, joint, values[at])
                at += 2  # position, velocity
        if at != len(values):
            raise ValueError(f"state vector has {len(values)} values, the world needs {at}")

    def frames(
        self, every: int = 3, start: float = 0.0, stop: float = float("inf")
    ) -> Iterator[dict[str, Any]]:
        """Yield a frame for every `every`-th 100 Hz state record with start <= t < stop."""
        import struct

        import msgpack

        from drcsim.rundir import STATE

        period = every * TICK_STEPS
        offset = max((o for t, o in self._marks if t <= start), default=0)
        with open(self.log_dir / STATE, "rb") as handle:
            handle.seek(offset)
            unpacker = msgpack.Unpacker(handle, raw=False)
            while True:
                at = offset + unpacker.tell()
                try:
                    record = next(unpacker)
                except StopIteration:
                    return
                t, step = float(record["t"]), int(record["step"])
                if step % (100 * TICK_STEPS) == 0:  # remember where each second starts
                    self._marks.add((t, at))
                if t >= stop:
                    return
                if step % period or t < start:
                    continue
                raw = record["state32"]
                self.apply(struct.unpack(f"<{len(raw) // 4}f", raw))
                yield pose_frame(self.client, self.bodies, t, step)

    def close(self) -> None:
        """Disconnect from the physics engine."""
        self.client.disconnect()


def world_scene(
    world: str, config: str | int, document: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Return the description of a world in a run configuration, as a run of it starts
    (from `document` if given, else the shipped copy)."""
    from drcsim.engine import RunOptions, Simulation

    sim = Simulation(world, config, RunOptions(world_document=document))
    try:
        return describe_scene(sim.client, scene_roles(sim))
    finally:
        sim.client.disconnect()


def scene_roles(sim: Any) -> dict[str, Any]:
    """Return which body is the robot (and its pelvis link), vehicle, and the gates' poses."""
    scene = sim.scene
    roles: dict[str, Any] = {"robot": scene.robot, "robot_link": 0}
    if scene.vehicle is not None:
        roles["vehicle"] = scene.vehicle
    roles["gates"] = {
        name: {"x": g.x, "y": g.y, "yaw": g.yaw, "width": g.width}
        for name, g in scene.gates.items()
    }
    return roles
