"""Task props: gates, table, hose with coupler, standpipe with inlet and valve."""

from __future__ import annotations

import math

from drcsim.urdf import Joint, Link, Robot, Vec3, box, capsule, cylinder

HALF_PI = math.pi / 2
TABLE_HEIGHT = 1.0
HOSE_SEGMENTS = 3
HOSE_SEGMENT_LENGTH = 0.25
# Standpipe geometry in its own frame (the robot faces it from -x).
# The inlet point lies just beyond the stub (x -0.07..-0.21), where a coupler can reach it.
INLET_XYZ: Vec3 = (-0.3, 0.0, 1.15)
INLET_AXIS: Vec3 = (-1.0, 0.0, 0.0)
VALVE_XYZ: Vec3 = (-0.12, -0.35, 1.3)
VALVE_RADIUS = 0.12

POST = (0.9, 0.5, 0.1, 1.0)
WOOD = (0.55, 0.4, 0.25, 1.0)
HOSE = (0.1, 0.3, 0.1, 1.0)
STEEL = (0.5, 0.5, 0.55, 1.0)
RED = (0.8, 0.1, 0.1, 1.0)


def build_gate(width: float, height: float = 2.5) -> Robot:
    """Return a static gate: two posts and a crossbar; the opening faces +x."""
    robot = Robot(f"gate_{width:g}")
    half = width / 2
    robot.add(
        Link(
            "frame",
            0.0,
            [
                box(0.15, 0.15, height, xyz=(0, half + 0.075, height / 2)),
                box(0.15, 0.15, height, xyz=(0, -half - 0.075, height / 2)),
                box(0.15, width + 0.3, 0.15, xyz=(0, 0, height)),
            ],
            rgba=POST,
        )
    )
    return robot


def build_table() -> Robot:
    """Return a static table whose top is TABLE_HEIGHT above the ground."""
    top = TABLE_HEIGHT - 0.025
    legs = [box(0.06, 0.06, top, xyz=(x * 0.5, y * 0.3, top / 2)) for x in (-1, 1) for y in (-1, 1)]
    robot = Robot("table")
    robot.add(Link("table", 0.0, [box(1.2, 0.8, 0.05, xyz=(0, 0, top)), *legs], rgba=WOOD))
    return robot


def build_hose() -> Robot:
    """Return a hose: the coupler (base, axis +x) and a few passive segments behind it."""
    robot = Robot("hose")
    robot.add(Link("coupler", 0.6, [cylinder(0.045, 0.16, rpy=(0, HALF_PI, 0))], rgba=STEEL))
    parent = "coupler"
    offset = -0.08
    for index in range(HOSE_SEGMENTS):
        name = f"segment_{index}"
        link = Link(
            name,
            0.3,
            [
                capsule(
                    0.03,
                    HOSE_SEGMENT_LENGTH - 0.06,
                    xyz=(-HOSE_SEGMENT_LENGTH / 2, 0, 0),
                    rpy=(0, HALF_PI, 0),
                )
            ],
            rgba=HOSE,
        )
        axis: Vec3 = (0, 0, 1) if index % 2 == 0 else (0, 1, 0)
        robot.add(
            link,
            Joint(
                f"hose_{index}",
                "revolute",
                parent,
                name,
                xyz=(offset, 0, 0),
                axis=axis,
                lower=-1.2,
                upper=1.2,
                velocity=10.0,
                effort=0.0,
                damping=0.5,
            ),
        )
        parent, offset = name, -HOSE_SEGMENT_LENGTH
    return robot


def build_standpipe() -> Robot:
    """Return a static standpipe with a side inlet and a valve wheel on a revolute joint."""
    robot = Robot("standpipe")
    pipe = Link(
        "pipe",
        0.0,
        [
            cylinder(0.07, 1.4, xyz=(0, 0, 0.7)),
            cylinder(0.05, 0.14, xyz=(-0.14, 0, INLET_XYZ[2]), rpy=(0, HALF_PI, 0)),
            box(0.05, 0.4, 0.05, xyz=(-0.05, -0.2, VALVE_XYZ[2])),
        ],
        rgba=STEEL,
        com=(0.0, 0.0, 0.0),  # constraint pivots and poses are relative to the COM frame
    )
    robot.add(pipe)
    wheel = Link(
        "valve",
        1.0,
        [cylinder(VALVE_RADIUS, 0.03, rpy=(0, HALF_PI, 0)), box(0.03, 2 * VALVE_RADIUS, 0.03)],
        rgba=RED,
    )
    robot.add(
        wheel,
        Joint(
            "valve",
            "continuous",
            "pipe",
            "valve",
            xyz=VALVE_XYZ,
            axis=(1, 0, 0),
            velocity=3.0,
            effort=50.0,
            damping=2.0,
        ),
    )
    return robot
