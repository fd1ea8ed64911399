"""A small electric utility vehicle driven only through its human interfaces."""

from __future__ import annotations

import math
from dataclasses import dataclass

from drcsim.urdf import Joint, Link, Robot, Vec3, box, cylinder

HALF_PI = math.pi / 2
WHEEL_RADIUS = 0.3
WHEEL_BASE_X = 0.95
TRACK_Y = 0.65
CHASSIS_HEIGHT = 0.45  # chassis centre above the ground when resting on its wheels


@dataclass(frozen=True)
class Interface:
    """A human interface: a joint the driver moves, and its travel."""

    joint: str
    lower: float
    upper: float
    xyz: Vec3
    axis: Vec3


INTERFACES: dict[str, Interface] = {
    "steering_wheel": Interface("steering_wheel", -3.0, 3.0, (0.35, 0.3, 0.45), (1, 0, 0)),
    "throttle_pedal": Interface("throttle_pedal", 0.0, 0.35, (0.44, 0.21, -0.12), (0, 1, 0)),
    "brake_pedal": Interface("brake_pedal", 0.0, 0.35, (0.44, 0.39, -0.12), (0, 1, 0)),
    "hand_brake": Interface("hand_brake", 0.0, 0.6, (0.05, 0.05, 0.25), (0, 1, 0)),
    "fnr_switch": Interface("fnr_switch", -0.3, 0.3, (0.3, 0.05, 0.4), (0, 1, 0)),
}
PEDALS = ("throttle_pedal", "brake_pedal")
PEDAL_HEIGHT = 0.12  # the pedal plate, up from its pivot
PEDAL_TILT = math.pi / 4  # the plate leans forward this far from upright at rest
STEERING_RATIO = 5.0  # steering wheel radians per road-wheel radian
MAX_STEER = 0.6
MAX_SPEED = 6.0  # m/s at full throttle
DRIVE_TORQUE = 400.0  # N m per driven wheel at full throttle
BRAKE_TORQUE = 900.0  # N m per wheel at full brake
HAND_BRAKE_TORQUE = 600.0
# Pelvis pose in the driver seat, relative to the chassis centre of mass.
SEAT_PELVIS_XYZ: Vec3 = (-0.15, 0.3, 0.5)
# Where the robot stands after getting out (driver side), relative to the chassis.
EXIT_STAND_XYZ: Vec3 = (-0.15, 1.35, 0.0)
# How close the pelvis must be to the driver door to get in (metres, horizontal).
ENTRY_REACH = 1.5
WHEELS = ("fl_wheel", "fr_wheel", "rl_wheel", "rr_wheel")
STEER_JOINTS = ("fl_steer", "fr_steer")
DRIVEN_WHEELS = ("rl_wheel", "rr_wheel")

BODY = (0.15, 0.45, 0.2, 1.0)
TRIM = (0.1, 0.1, 0.1, 1.0)


def build_vehicle() -> Robot:
    """Return the vehicle's URDF model (chassis, four wheels, front steering, interfaces)."""
    robot = Robot("utility_vehicle")
    chassis = Link("chassis", 550.0, [box(2.4, 1.3, 0.25)], rgba=BODY)
    chassis.shapes.append(box(0.5, 0.9, 0.25, xyz=(-0.15, 0.0, 0.25)))  # bench seat
    chassis.shapes.append(box(0.05, 1.3, 0.9, xyz=(-0.45, 0.0, 0.57)))  # seat back / cage
    chassis.shapes.append(box(0.7, 1.3, 0.3, xyz=(0.85, 0.0, 0.27)))  # dash and bonnet
    robot.add(chassis)
    for name, x, y in (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1), ("rr", -1, -1)):
        wheel_parent = "chassis"
        xyz: Vec3 = (x * WHEEL_BASE_X, y * TRACK_Y, -0.15)
        if x > 0:
            knuckle = Link(f"{name}_knuckle", 5.0, [box(0.05, 0.05, 0.05)], collide=False)
            robot.add(
                knuckle,
                Joint(
                    f"{name}_steer",
                    "revolute",
                    "chassis",
                    knuckle.name,
                    xyz=xyz,
                    axis=(0, 0, 1),
                    lower=-MAX_STEER,
                    upper=MAX_STEER,
                    velocity=3.0,
                    effort=2000.0,
                ),
            )
            wheel_parent, xyz = knuckle.name, (0.0, 0.0, 0.0)
        wheel = Link(
            f"{name}_wheel", 15.0, [cylinder(WHEEL_RADIUS, 0.2, rpy=(HALF_PI, 0, 0))], rgba=TRIM
        )
        robot.add(
            wheel,
            Joint(
                f"{name}_wheel",
                "continuous",
                wheel_parent,
                wheel.name,
                xyz=xyz,
                axis=(0, 1, 0),
                velocity=40.0,
                effort=BRAKE_TORQUE,
            ),
        )
    for interface in INTERFACES.values():
        shape = (
            cylinder(0.18, 0.03, rpy=(0, HALF_PI, 0))
            if interface.joint == "steering_wheel"
            else box(
                0.04,
                0.08,
                PEDAL_HEIGHT,
                xyz=(
                    math.sin(PEDAL_TILT) * PEDAL_HEIGHT / 2,
                    0,
                    math.cos(PEDAL_TILT) * PEDAL_HEIGHT / 2,
                ),
                rpy=(0, PEDAL_TILT, 0),
            )
            if interface.joint in PEDALS
            else box(0.04, 0.08, 0.12, xyz=(0, 0, 0.06))
        )
        # The driver's feet press the pedals (contact); the hands hold the rest (grasp joints).
        pedal = interface.joint in PEDALS
        link = Link(interface.joint, 0.5, [shape], rgba=TRIM, collide=pedal)
        robot.add(
            link,
            Joint(
                interface.joint,
                "revolute",
                "chassis",
                link.name,
                xyz=interface.xyz,
                axis=interface.axis,
                lower=interface.lower,
                upper=interface.upper,
                velocity=6.0,
                effort=200.0,
            ),
        )
    return robot
