"""Physics assists, the same for every team: balance harness, grasp, seat, coupling."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

from drcsim._bullet import BulletClient, pybullet
from drcsim.control import JointController
from drcsim.driving import VehicleDrive
from drcsim.errors import CommandError
from drcsim.models import humanoid, props, vehicle
from drcsim.scene import Scene, yaw_quaternion

HARNESS_FORCE = 6000.0  # N (and N m): enough to carry the robot, not to throw vehicles about
GRASP_RADIUS = 0.12  # palm to object centre, metres
GRASP_FORCE = 800.0
HANDLE_REACH = 0.05  # palm to a rim or a lever's end, metres
SEAT_FORCE = 50000.0
GRIPPER_CLOSED = 0.04


class Harness:
    """Balance assist: a force-limited constraint that holds the pelvis upright at a pose."""

    def __init__(self, client: BulletClient, robot: int) -> None:
        self.client = client
        pos, orn = client.getBasePositionAndOrientation(robot)
        # The pose goes in the child (world) frame: as parentFrameOrientation it was
        # composed with every later hold() and turned any start yaw back to 0.
        self.constraint = client.createConstraint(
            robot,
            -1,
            -1,
            -1,
            pybullet.JOINT_FIXED,
            [0, 0, 0],
            [0, 0, 0],
            pos,
            childFrameOrientation=orn,
        )
        self.active = False
        self.release()

    def hold(self, x: float, y: float, z: float, yaw: float) -> None:
        """Hold the pelvis at (x, y, z), upright, facing `yaw`."""
        self.client.changeConstraint(
            self.constraint, [x, y, z], yaw_quaternion(yaw), maxForce=HARNESS_FORCE
        )
        self.active = True

    def release(self) -> None:
        """Let go of the pelvis: only the joints hold the robot up."""
        self.client.changeConstraint(self.constraint, maxForce=0.0)
        self.active = False


def _point_distance(
    a: tuple[float, ...] | list[float], b: tuple[float, ...] | list[float]
) -> float:
    return math.dist(a[:3], b[:3])


class Holdable(Protocol):
    """A rim or lever a closed hand can hold (drcsim.handles.Handle)."""

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

    def locate(self, scene: Scene, world: Any) -> tuple[float, float]:
        """Return the angle about the axis of `world` and its distance to the grip."""
        ...


class Grasps:
    """Grasp assist: closing a hand near an object fixes the object to the hand."""

    def __init__(self, scene: Scene, controller: JointController) -> None:
        self.scene = scene
        self.client = scene.client
        self.controller = controller
        self.held: dict[str, tuple[int, str]] = {}
        self.hose_connected = False
        self.handles: list[Holdable] = []
        if scene.hose is not None:
            # Hands pass through the hose so that closing on it never knocks it away.
            hands = [n for n in scene.robot_links if n[2:] in ("hand", "finger", "larm", "ufarm")]
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
        return self._close_on_hose(hand) or self._close_on_handle(hand)

    def _close_on_handle(self, hand: str) -> str | None:
        """Hold the rim or lever the palm is at: a point-to-point grasp joint at the palm."""
        palm = self.palm(hand)
        for handle in self.handles:
            _, distance = handle.locate(self.scene, palm)
            if distance > HANDLE_REACH or self.holding(handle.name):
                continue
            link_pos, link_orn = self.client.getLinkState(handle.body, handle.joint)[:2]
            inv_pos, inv_orn = self.client.invertTransform(link_pos, link_orn)
            pivot, _ = self.client.multiplyTransforms(inv_pos, inv_orn, palm, [0, 0, 0, 1])
            link = self.scene.robot_links[humanoid.HAND_LINKS[hand]]
            constraint = self.client.createConstraint(
                self.scene.robot,
                link,
                handle.body,
                handle.joint,
                pybullet.JOINT_POINT2POINT,
                [0, 0, 0],
                [0, 0, 0],
                pivot,
            )
            self.client.changeConstraint(constraint, maxForce=GRASP_FORCE)
            self.held[hand] = (constraint, handle.name)
            return handle.name
        return None

    def _close_on_hose(self, hand: str) -> str | None:
        hose = self.scene.hose
        if hose is None or self.hose_connected or any(n == "hose" for _, n in self.held.values()):
            return None
        hose_pos, hose_orn = self.client.getBasePositionAndOrientation(hose)
        if _point_distance(self.palm(hand), hose_pos) > GRASP_RADIUS:
            return None
        link = self.scene.robot_links[humanoid.HAND_LINKS[hand]]
        hand_pos, hand_orn = self.client.getLinkState(self.scene.robot, link)[:2]
        inv_pos, inv_orn = self.client.invertTransform(hand_pos, hand_orn)
        rel_pos, rel_orn = self.client.multiplyTransforms(inv_pos, inv_orn, hose_pos, hose_orn)
        constraint = self.client.createConstraint(
            self.scene.robot,
            link,
            hose,
            -1,
            pybullet.JOINT_FIXED,
            [0, 0, 0],
            rel_pos,
            [0, 0, 0],
            rel_orn,
        )
        self.client.changeConstraint(constraint, maxForce=GRASP_FORCE)
        self._ignore_collisions(hose, list(self.scene.robot_links.values()))
        self.held[hand] = (constraint, "hose")
        return "hose"

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
