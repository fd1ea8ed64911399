"""Physics assists, the same for every team: grasp, seat, coupling."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

from drcsim._bullet import pybullet
from drcsim.control import JointController
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.models import humanoid, props, vehicle
from drcsim.scene import Scene, yaw_quaternion

GRASP_FORCE = 800.0
HANDLE_REACH = 0.05  # palm to a rim, a lever's end or the coupler's axis, metres
# The middle of the coupler's 0.16 m sleeve a palm may be at: within HANDLE_REACH of it, the
# hand is around the sleeve and never beyond its ends.
COUPLER_GRIP = 0.03
# The gripper closes along the hand's z axis; it surrounds a sleeve only when it closes
# within 45 degrees of square to the sleeve's axis (along it, the jaws would meet its ends,
# 0.16 m apart, with 0.04 m of opening).
JAWS_ACROSS = math.cos(math.radians(45.0))
SEAT_FORCE = 50000.0
# The links that pass through what a hand closes on (the fingers do not wrap around it).
HAND_PARTS = ("hand", "finger", "larm", "ufarm")
GRIPPER_CLOSED = 0.04


def _point_distance(
    a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float]
) -> float:
    return math.dist(a[:3], b[:3])


class Holdable(Protocol):
    """A rim, lever or sleeve a closed hand can hold (drcsim.handles.Handle, Sleeve below)."""

    @property
    def name(self) -> str:
        """Return the handle's name (what `grasp` reports)."""
        ...

    @property
    def body(self) -> int:
        """Return the body the handle belongs to."""
        ...

    @property
    def joint(self) -> int:
        """Return the handle's joint (and link) index."""
        ...

    @property
    def carried(self) -> bool:
        """Return whether the hand carries it rigidly (a free object) or pivots on it."""
        ...

    def locate(self, scene: Scene, world: Any) -> tuple[float, float]:
        """Return where along the grip `world` is and its distance to the grip."""
        ...

    def between_jaws(self, scene: Scene, closing: Any) -> bool:
        """Return whether jaws closing along the world direction `closing` surround it."""
        ...


@dataclass(frozen=True)
class Sleeve:
    """A free object's straight grip (the hose's coupler): held along its axis's middle."""

    name: str
    body: int
    half_length: float  # of the stretch of the axis (link +x) the palm may be at
    joint: int = -1  # the base link
    carried: bool = True

    def locate(self, scene: Scene, world: Any) -> tuple[float, float]:
        """Return how far along the axis `world` is and its distance to the grip's stretch."""
        client = scene.client
        inv_pos, inv_orn = client.invertTransform(*client.getBasePositionAndOrientation(self.body))
        local, _ = client.multiplyTransforms(inv_pos, inv_orn, list(world), [0, 0, 0, 1])
        along = max(-self.half_length, min(self.half_length, local[0]))
        return along, math.dist(local, (along, 0.0, 0.0))

    def between_jaws(self, scene: Scene, closing: Any) -> bool:
        """Return whether jaws closing along `closing` close across the sleeve's axis."""
        orientation = scene.client.getBasePositionAndOrientation(self.body)[1]
        axis = scene.client.getMatrixFromQuaternion(orientation)[0::3]  # the link's +x
        return abs(sum(a * c for a, c in zip(axis, closing, strict=True))) <= JAWS_ACROSS


class Grasps:
    """Grasp assist: closing a hand around a holdable grip joins it to the hand."""

    def __init__(self, scene: Scene, controller: JointController) -> None:
        self.scene = scene
        self.client = scene.client
        self.controller = controller
        self.held: dict[str, tuple[int, str]] = {}
        self.hose_connected = False
        self.handles: list[Holdable] = []
        if scene.hose is not None:
            self.handles.append(Sleeve("hose", scene.hose, COUPLER_GRIP))
            # Hands pass through the hose so that closing on it never knocks it away (the
            # fingers do not wrap around it, as on the rims).
            hands = [n for n in scene.robot_links if n[2:] in HAND_PARTS]
            self._ignore_collisions(scene.hose, [scene.robot_links[n] for n in hands])
            if scene.standpipe is not None:
                # The coupler slides onto the inlet; the coupling assist makes the joint.
                for hose_link in range(-1, self.client.getNumJoints(scene.hose)):
                    self.client.setCollisionFilterPair(
                        scene.hose, scene.standpipe, hose_link, -1, 0
                    )

    def _ignore_collisions(self, body: int, robot_links: list[int]) -> None:
        for robot_link in robot_links:
            for link in range(-1, self.client.getNumJoints(body)):
                self.client.setCollisionFilterPair(self.scene.robot, body, robot_link, link, 0)

    def palm(self, hand: str) -> tuple[float, float, float]:
        """Return the world position of a hand's grasp point (the hand link's COM)."""
        link = self.scene.robot_links[humanoid.HAND_LINKS[hand]]
        return tuple(self.client.getLinkState(self.scene.robot, link)[0])  # type: ignore[return-value]

    def close(self, hand: str) -> str | None:
        """Close `hand`; return the name of the object grasped, if any."""
        self.controller.set_position(f"{hand[0]}_gripper", GRIPPER_CLOSED)
        if hand in self.held:
            return self.held[hand][1]
        palm = self.palm(hand)
        closing = self._closing(hand)
        for handle in self.handles:
            _, distance = handle.locate(self.scene, palm)
            around = distance <= HANDLE_REACH and handle.between_jaws(self.scene, closing)
            if around and not self.holding(handle.name):
                self.held[hand] = (self._grasp_joint(hand, handle, palm), handle.name)
                return handle.name
        return None  # closed on nothing: the hand is not around anything holdable

    def _closing(self, hand: str) -> tuple[float, float, float]:
        """Return the world direction a hand's gripper closes along (its link's z axis)."""
        link = self.scene.robot_links[humanoid.HAND_LINKS[hand]]
        orientation = self.client.getLinkState(self.scene.robot, link)[1]
        return tuple(self.client.getMatrixFromQuaternion(orientation)[2::3])  # type: ignore[return-value]

    def _grasp_joint(self, hand: str, handle: Holdable, palm: tuple[float, ...]) -> int:
        """Make the grasp joint: fixed for a carried object, else a pivot at the palm."""
        client = self.client
        link = self.scene.robot_links[humanoid.HAND_LINKS[hand]]
        if handle.carried:
            pose = client.getBasePositionAndOrientation(handle.body)
            hand_pos, hand_orn = client.getLinkState(self.scene.robot, link)[:2]
            inv_pos, inv_orn = client.invertTransform(hand_pos, hand_orn)
            rel_pos, rel_orn = client.multiplyTransforms(inv_pos, inv_orn, *pose)
            joint = pybullet.JOINT_FIXED
            frames: tuple[Any, ...] = ([0, 0, 0], rel_pos, [0, 0, 0], rel_orn)
            # Carried, it must not catch on the arm that holds it.
            self._ignore_collisions(handle.body, list(self.scene.robot_links.values()))
        else:
            link_pos, link_orn = client.getLinkState(handle.body, handle.joint)[:2]
            inv_pos, inv_orn = client.invertTransform(link_pos, link_orn)
            pivot, _ = client.multiplyTransforms(inv_pos, inv_orn, palm, [0, 0, 0, 1])
            joint = pybullet.JOINT_POINT2POINT
            frames = ([0, 0, 0], [0, 0, 0], pivot)
        constraint = client.createConstraint(
            self.scene.robot, link, handle.body, handle.joint, joint, *frames
        )
        client.changeConstraint(constraint, maxForce=GRASP_FORCE)
        return constraint

    def open(self, hand: str) -> None:
        """Open `hand`, letting go of whatever it holds."""
        self.controller.set_position(f"{hand[0]}_gripper", 0.0)
        if hand in self.held:
            self.client.removeConstraint(self.held.pop(hand)[0])

    def holding(self, name: str) -> str | None:
        """Return which hand holds object `name`, if any."""
        for hand, (_, held) in self.held.items():
            if held == name:
                return hand
        return None


@dataclass
class Coupling:
    """Coupling assist: a hose held within tolerance of the inlet long enough is connected."""

    scene: Scene
    grasps: Grasps
    distance: float
    hold_ticks: int
    ticks_in_range: int = 0

    def inlet(self) -> tuple[float, float, float]:
        """Return the inlet point in world coordinates."""
        assert self.scene.standpipe is not None
        pos, orn = self.scene.client.getBasePositionAndOrientation(self.scene.standpipe)
        return tuple(
            self.scene.client.multiplyTransforms(pos, orn, props.INLET_XYZ, [0, 0, 0, 1])[0]
        )  # type: ignore[return-value]

    def hose_distance(self) -> float:
        """Return the distance from the coupler to the inlet."""
        assert self.scene.hose is not None
        pos, _ = self.scene.client.getBasePositionAndOrientation(self.scene.hose)
        return _point_distance(pos, self.inlet())

    def tick(self) -> bool:
        """Check the tolerance (100 Hz); connect when it has held; return whether connected."""
        if self.grasps.hose_connected or self.scene.hose is None:
            return self.grasps.hose_connected
        hand = self.grasps.holding("hose")
        in_range = hand is not None and self.hose_distance() <= self.distance
        self.ticks_in_range = self.ticks_in_range + 1 if in_range else 0
        if hand is None or self.ticks_in_range < self.hold_ticks:
            return False
        client, hose, pipe = self.scene.client, self.scene.hose, self.scene.standpipe
        assert pipe is not None
        self.grasps.open(hand)
        self.grasps.handles = [h for h in self.grasps.handles if h.body != hose]
        _, pipe_orn = client.getBasePositionAndOrientation(pipe)
        client.resetBasePositionAndOrientation(hose, self.inlet(), pipe_orn)
        client.resetBaseVelocity(hose, [0, 0, 0], [0, 0, 0])
        constraint = client.createConstraint(
            pipe, -1, hose, -1, pybullet.JOINT_FIXED, [0, 0, 0], props.INLET_XYZ, [0, 0, 0]
        )
        client.changeConstraint(constraint, maxForce=SEAT_FORCE)
        self.grasps.hose_connected = True
        return True


class Seat:
    """Seat assist: moves the robot into or out of the driver seat when it is close enough."""

    def __init__(self, scene: Scene, controller: JointController, drive: VehicleDrive | None):
        self.scene = scene
        self.controller = controller
        self.drive = drive
        self.constraint: int | None = None

    @property
    def seated(self) -> bool:
        """Return whether the robot sits in the driver seat."""
        return self.constraint is not None

    def _vehicle_pose(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        assert self.scene.vehicle is not None
        pos, orn = self.scene.client.getBasePositionAndOrientation(self.scene.vehicle)
        return tuple(pos), tuple(orn)

    def _set_vehicle_collisions(self, enabled: bool) -> None:
        client, robot, car = self.scene.client, self.scene.robot, self.scene.vehicle
        assert car is not None
        for robot_link in range(-1, client.getNumJoints(robot)):
            for car_link in range(-1, client.getNumJoints(car)):
                client.setCollisionFilterPair(robot, car, robot_link, car_link, int(enabled))

    def enter(self) -> None:
        """Put the robot in the driver seat; raise if it is not at the driver door."""
        if self.drive is None or self.scene.vehicle is None:
            raise CommandError("this world has no vehicle")
        if self.seated:
            raise CommandError("the robot is already in the vehicle")
        client = self.scene.client
        car_pos, car_orn = self._vehicle_pose()
        door, _ = client.multiplyTransforms(car_pos, car_orn, vehicle.EXIT_STAND_XYZ, [0, 0, 0, 1])
        pelvis, _ = client.getBasePositionAndOrientation(self.scene.robot)
        if math.hypot(pelvis[0] - door[0], pelvis[1] - door[1]) > vehicle.ENTRY_REACH:
            raise CommandError(
                f"the robot is not at the driver door (within "
                f"{vehicle.ENTRY_REACH} m of {[round(v, 2) for v in door[:2]]})"
            )
        if self.drive.speed() > 0.5:
            raise CommandError("the vehicle is moving")
        self._set_vehicle_collisions(False)
        seat_pos, _ = client.multiplyTransforms(
            car_pos, car_orn, vehicle.SEAT_PELVIS_XYZ, [0, 0, 0, 1]
        )
        client.resetBasePositionAndOrientation(self.scene.robot, seat_pos, car_orn)
        client.resetBaseVelocity(self.scene.robot, [0, 0, 0], [0, 0, 0])
        self.controller.reset_to(humanoid.SIT_POSTURE)
        self.constraint = client.createConstraint(
            self.scene.vehicle,
            -1,
            self.scene.robot,
            -1,
            pybullet.JOINT_FIXED,
            [0, 0, 0],
            vehicle.SEAT_PELVIS_XYZ,
            [0, 0, 0],
        )
        client.changeConstraint(self.constraint, maxForce=SEAT_FORCE)

    def check_exit(self) -> None:
        """Raise CommandError unless the robot may get out now."""
        if self.drive is None or self.constraint is None:
            raise CommandError("the robot is not in the vehicle")
        if self.drive.speed() > 0.5:
            raise CommandError("the vehicle is moving")

    def exit(self) -> tuple[float, float, float]:
        """Stand the robot beside the driver door; return its (x, y, yaw)."""
        self.check_exit()
        assert self.constraint is not None
        client = self.scene.client
        client.removeConstraint(self.constraint)
        self.constraint = None
        car_pos, car_orn = self._vehicle_pose()
        door, _ = client.multiplyTransforms(car_pos, car_orn, vehicle.EXIT_STAND_XYZ, [0, 0, 0, 1])
        yaw = client.getEulerFromQuaternion(car_orn)[2]
        z = humanoid.STAND_PELVIS_HEIGHT + self.scene.ground_height(door[0], door[1])
        client.resetBasePositionAndOrientation(
            self.scene.robot, [door[0], door[1], z], yaw_quaternion(yaw)
        )
        client.resetBaseVelocity(self.scene.robot, [0, 0, 0], [0, 0, 0])
        self.controller.reset_to(humanoid.STAND_POSTURE)
        self._set_vehicle_collisions(True)
        return door[0], door[1], yaw
