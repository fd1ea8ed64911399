"""Build a world's bodies in a pybullet client: ground, terrain, robot, vehicle and props."""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drcsim._bullet import BulletClient, pybullet
from drcsim.errors import WorldError
from drcsim.models import humanoid, props, vehicle
from drcsim.mud import MudPit
from drcsim.urdf import Robot
from drcsim.worlds import WorldSpec

TIMESTEP = 0.001
TICK_STEPS = 10  # physics steps per 100 Hz tick: scoring, state log, clock, walking pattern
SOLVER_ITERATIONS = 20
MUD_BOTTOM = 0.002  # m: the top of a mud pit's firm bottom over the ground
MODEL_CACHE = Path(tempfile.gettempdir()) / "drcsim-models"


@dataclass(frozen=True)
class TerrainPatch:
    """A rectangle of ground with its own walking speed factor and surface height."""

    kind: str
    lower: tuple[float, float]
    upper: tuple[float, float]
    height: float
    ramp: float = 0.0  # hills: length of the slope at each end (the top is `height` high)

    def contains(self, x: float, y: float) -> bool:
        """Return whether the point (x, y) lies over this patch."""
        return self.lower[0] <= x <= self.upper[0] and self.lower[1] <= y <= self.upper[1]

    def surface(self, x: float) -> float:
        """Return the walking surface height at `x` (inside the patch)."""
        if self.ramp <= 0.0:
            return self.height
        into = min(x - self.lower[0], self.upper[0] - x)
        return self.height * max(0.0, min(1.0, into / self.ramp))


@dataclass(frozen=True)
class Gate:
    """A gate's pose (x, y, yaw) and opening width."""

    body: int
    x: float
    y: float
    yaw: float
    width: float


@dataclass
class Scene:
    """Body ids and joint/link indices of everything a world contains."""

    client: BulletClient
    robot: int
    robot_joints: dict[str, int]
    robot_links: dict[str, int]
    ground: int
    vehicle: int | None = None
    vehicle_joints: dict[str, int] = field(default_factory=dict)
    hose: int | None = None
    standpipe: int | None = None
    table: int | None = None
    gates: dict[str, Gate] = field(default_factory=dict)
    terrain: list[TerrainPatch] = field(default_factory=list)
    rubble: list[int] = field(default_factory=list)
    mud: list[MudPit] = field(default_factory=list)
    course: dict[str, Any] = field(default_factory=dict)

    def terrain_at(self, x: float, y: float) -> TerrainPatch | None:
        """Return the terrain patch under (x, y), if any (else paved ground)."""
        for patch in self.terrain:
            if patch.contains(x, y):
                return patch
        return None

    def ground_height(self, x: float, y: float) -> float:
        """Return the walking surface height under (x, y)."""
        patch = self.terrain_at(x, y)
        return patch.surface(x) if patch else 0.0


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """Return the quaternion of a rotation by `yaw` about z."""
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def local_to_world(pose: list[float], xyz: tuple[float, float, float]) -> list[float]:
    """Return a point given in the frame of a planar pose (x, y, yaw) in world coordinates."""
    x, y, yaw = pose[0], pose[1], pose[2]
    c, s = math.cos(yaw), math.sin(yaw)
    return [x + c * xyz[0] - s * xyz[1], y + s * xyz[0] + c * xyz[1], xyz[2]]


def _joint_maps(client: BulletClient, body: int) -> tuple[dict[str, int], dict[str, int]]:
    joints: dict[str, int] = {}
    links: dict[str, int] = {}
    for index in range(client.getNumJoints(body)):
        info = client.getJointInfo(body, index)
        joints[info[1].decode()] = index
        links[info[12].decode()] = index
    return joints, links


def _load(client: BulletClient, model: Robot, xyz: list[float], yaw: float) -> int:
    path = model.write(MODEL_CACHE)
    flags = pybullet.URDF_USE_INERTIA_FROM_FILE
    return int(client.loadURDF(str(path), xyz, yaw_quaternion(yaw), flags=flags))


def _static_box(
    client: BulletClient,
    half: list[float],
    centre: list[float],
    yaw: float,
    rgba: list[float],
    pitch: float = 0.0,
    mass: float = 0.0,
) -> int:
    shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
    visual = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=rgba)
    orientation = client.getQuaternionFromEuler([0.0, pitch, yaw])
    return int(client.createMultiBody(mass, shape, visual, centre, orientation))


def _mud(
    client: BulletClient, patch: dict[str, Any], centre: list[float], half: list[float]
) -> MudPit:
    # As the VRC's MudPlugin: the mud's surface holds nothing up (no collision shape: links
    # pass through it) and its drag is mud.MudDrag's; feet stand on the firm bottom, a rigid
    # box with the mud's friction whose top is MUD_BOTTOM over the ground (so that the plane
    # under it never touches a foot on it, and a sole across the rim barely tilts).
    depth = float(patch["depth"])
    bottom = _static_box(
        client, [*half, 0.05], [*centre, MUD_BOTTOM - 0.05], 0.0, [0.3, 0.22, 0.1, 1]
    )
    client.changeDynamics(bottom, -1, lateralFriction=float(patch["friction"]))
    visual = client.createVisualShape(
        pybullet.GEOM_BOX, halfExtents=[*half, depth / 2], rgbaColor=[0.4, 0.3, 0.12, 0.6]
    )
    client.createMultiBody(0, -1, visual, [*centre, MUD_BOTTOM + depth / 2])
    lower = (centre[0] - half[0], centre[1] - half[1])
    upper = (centre[0] + half[0], centre[1] + half[1])
    return MudPit(lower, upper, MUD_BOTTOM, MUD_BOTTOM + depth, float(patch["damping"]))


def _rubble(
    client: BulletClient, patch: dict[str, Any], rng: np.random.Generator, scene: Scene
) -> None:
    # Loose blocks of varied size that move when stepped on, placed without overlaps.
    lower, upper = patch["min"], patch["max"]
    placed: list[tuple[float, float, float]] = []
    density = float(patch.get("density", 900.0))
    for _ in range(int(patch["blocks"])):
        size = rng.uniform([0.12, 0.12, 0.03], [0.4, 0.4, float(patch["max_height"])])
        radius = float(math.hypot(size[0], size[1]) / 2)
        for _attempt in range(20):
            x = float(rng.uniform(lower[0] + radius, upper[0] - radius))
            y = float(rng.uniform(lower[1] + radius, upper[1] - radius))
            if all(math.hypot(x - px, y - py) > radius + pr for px, py, pr in placed):
                break
        else:
            continue
        placed.append((x, y, radius))
        block = _static_box(
            client,
            list(size / 2),
            [x, y, float(size[2]) / 2 + 0.001],
            float(rng.uniform(-math.pi, math.pi)),
            [0.5, 0.5, 0.45, 1],
            mass=float(np.prod(size)) * density,
        )
        client.changeDynamics(block, -1, lateralFriction=float(patch["friction"]))
        scene.rubble.append(block)


def _hill(
    client: BulletClient, patch: dict[str, Any], half: list[float], centre: list[float]
) -> float:
    # Up a slope, across a flat top, down again (along x); `rise` m high, `slope` degrees.
    rise, slope = float(patch["rise"]), math.radians(float(patch["slope"]))
    ramp = rise / math.tan(slope)
    lower_x, upper_x = patch["min"][0], patch["max"][0]
    thick = 0.2
    top = upper_x - lower_x - 2 * ramp
    colour = [0.45, 0.5, 0.35, 1]
    _static_box(
        client, [top / 2, half[1], thick / 2], [centre[0], centre[1], rise - thick / 2], 0.0, colour
    )
    length = math.hypot(ramp, rise)
    for sign, start in ((1, lower_x), (-1, upper_x)):
        # A plank whose top face runs from the ground at `start` to the top of the hill.
        mid_x = start + sign * ramp / 2
        normal_x, normal_z = -sign * math.sin(slope), math.cos(slope)
        body = _static_box(
            client,
            [length / 2, half[1], thick / 2],
            [mid_x - normal_x * thick / 2, centre[1], rise / 2 - normal_z * thick / 2],
            0.0,
            colour,
            pitch=-sign * slope,
        )
        client.changeDynamics(body, -1, lateralFriction=float(patch.get("friction", 0.9)))
    return ramp


def _build_terrain(client: BulletClient, spec: WorldSpec, scene: Scene) -> None:
    for patch_id, patch in spec.terrain.items():
        lower, upper = patch["min"], patch["max"]
        centre = [(lower[0] + upper[0]) / 2, (lower[1] + upper[1]) / 2]
        half = [(upper[0] - lower[0]) / 2, (upper[1] - lower[1]) / 2]
        height, ramp = 0.0, 0.0
        if patch["kind"] == "mud":
            pit = _mud(client, patch, centre, half)
            scene.mud.append(pit)
            height = pit.bottom
        elif patch["kind"] == "rubble":
            pass  # loose blocks come after the robot (see build_scene)
        elif patch["kind"] == "hill":
            ramp = _hill(client, patch, half, centre)
            height = float(patch["rise"])
        else:
            raise WorldError(f"terrain patch {patch_id!r} has unknown kind {patch['kind']!r}")
        scene.terrain.append(
            TerrainPatch(
                patch["kind"],
                (lower[0], lower[1]),
                (upper[0], upper[1]),
                height,
                ramp,
            )
        )


def _build_objects(client: BulletClient, spec: WorldSpec, scene: Scene) -> None:
    for object_id, item in spec.objects.items():
        pose = [float(v) for v in item["pose"]]
        model = item["model"]
        if model == "gate":
            body = _load(
                client, props.build_gate(float(item["width"])), [pose[0], pose[1], 0.0], pose[2]
            )
            scene.gates[object_id] = Gate(body, pose[0], pose[1], pose[2], float(item["width"]))
            scene.course.setdefault("gates", {})[object_id] = {"pose": pose, "width": item["width"]}
        elif model == "vehicle":
            xyz = [pose[0], pose[1], vehicle.CHASSIS_HEIGHT]
            scene.vehicle = _load(client, vehicle.build_vehicle(), xyz, pose[2])
            scene.vehicle_joints, _ = _joint_maps(client, scene.vehicle)
            for wheel in vehicle.WHEELS:
                client.changeDynamics(
                    scene.vehicle, scene.vehicle_joints[wheel], lateralFriction=1.2
                )
            scene.course["vehicle"] = {
                "pose": pose,
                "driver_door": local_to_world(pose, vehicle.EXIT_STAND_XYZ),
            }
        elif model == "table":
            scene.table = _load(client, props.build_table(), [pose[0], pose[1], 0.0], pose[2])
            scene.course["table"] = {"pose": pose, "height": props.TABLE_HEIGHT}
        elif model == "hose":
            z = props.TABLE_HEIGHT + 0.045
            scene.hose = _load(client, props.build_hose(), [pose[0], pose[1], z], pose[2])
            for joint in range(client.getNumJoints(scene.hose)):
                client.setJointMotorControl2(
                    scene.hose, joint, pybullet.VELOCITY_CONTROL, force=0.2
                )
            scene.course["hose"] = {"coupler": [pose[0], pose[1], z]}
        elif model == "standpipe":
            scene.standpipe = _load(
                client, props.build_standpipe(), [pose[0], pose[1], 0.0], pose[2]
            )
            client.setJointMotorControl2(scene.standpipe, 0, pybullet.VELOCITY_CONTROL, force=0.5)
            scene.course["standpipe"] = {
                "pose": pose,
                "inlet": local_to_world(pose, props.INLET_XYZ),
                "valve": local_to_world(pose, props.VALVE_XYZ),
            }
        else:
            raise WorldError(f"object {object_id!r} has unknown model {model!r}")


def build_scene(client: BulletClient, spec: WorldSpec) -> Scene:
    """Create every body of `spec` in a freshly reset `client` and return their ids."""
    client.resetSimulation()
    client.setTimeStep(TIMESTEP)
    client.setGravity(0, 0, -9.81)
    client.setPhysicsEngineParameter(
        numSolverIterations=SOLVER_ITERATIONS, deterministicOverlappingPairs=1
    )
    plane = client.createCollisionShape(pybullet.GEOM_PLANE)
    ground = int(client.createMultiBody(0, plane))
    client.changeDynamics(ground, -1, lateralFriction=spec.ground_friction)
    x, y, yaw = spec.robot_start
    scene = Scene(client, robot=-1, robot_joints={}, robot_links={}, ground=ground)
    _build_terrain(client, spec, scene)
    z = humanoid.STAND_PELVIS_HEIGHT + scene.ground_height(x, y)
    scene.robot = _load(client, humanoid.build_humanoid(), [x, y, z], yaw)
    scene.robot_joints, scene.robot_links = _joint_maps(client, scene.robot)
    for link in (scene.robot_links["l_foot"], scene.robot_links["r_foot"]):
        client.changeDynamics(scene.robot, link, lateralFriction=1.0)
    # Loose rubble after the robot, so the robot stays the first moving body.
    rng = np.random.default_rng(spec.seed)
    for patch in spec.terrain.values():
        if patch["kind"] == "rubble":
            _rubble(client, patch, rng, scene)
    _build_objects(client, spec, scene)
    scene.course["robot_start"] = list(spec.robot_start)
    return scene
