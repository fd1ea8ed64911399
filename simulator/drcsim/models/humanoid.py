"""An Atlas-like humanoid: Atlas v5's 28-DoF joint names, limits and masses, plus grippers."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drcsim.urdf import Joint, Link, Robot, Vec3, box, capsule, sphere

HALF_PI = math.pi / 2


@dataclass(frozen=True)
class JointSpec:
    """One actuated joint: where it sits, its axis and its limits."""

    name: str
    parent: str
    child: str
    xyz: Vec3
    axis: Vec3
    lower: float
    upper: float
    velocity: float
    effort: float
    kp: float
    kd: float


X: Vec3 = (1.0, 0.0, 0.0)
Y: Vec3 = (0.0, 1.0, 0.0)
Z: Vec3 = (0.0, 0.0, 1.0)
AXES = {"x": X, "y": Y, "z": Z}
Row = tuple[Any, ...]

# One row per joint of the left side and the trunk (the right side mirrors y and the
# asymmetric limits): name, parent, child, origin, axis, lower, upper, velocity, effort, kp, kd.
# Limits and efforts follow Atlas v5.
_TRUNK = [
    ("back_bkz", "pelvis", "ltorso", (-0.0125, 0, 0.09), "z", -0.663, 0.663, 12, 106, 1500, 40),
    ("back_bky", "ltorso", "mtorso", (0, 0, 0.162), "y", -0.219, 0.538, 9, 445, 3000, 60),
    ("back_bkx", "mtorso", "utorso", (0, 0, 0.05), "x", -0.523, 0.523, 12, 300, 3000, 60),
    ("neck_ry", "utorso", "head", (0.1, 0, 0.55), "y", -0.602, 1.145, 6.28, 25, 80, 2),
]
_LEFT_LIMBS = [
    ("l_leg_hpz", "pelvis", "l_uglut", (0, 0.09, -0.05), "z", -0.174, 0.786, 12, 275, 1500, 30),
    ("l_leg_hpx", "l_uglut", "l_lglut", (0, 0, 0), "x", -0.523, 0.523, 12, 530, 3000, 60),
    ("l_leg_hpy", "l_lglut", "l_uleg", (0, 0, 0), "y", -1.61, 0.65, 12, 840, 3000, 60),
    ("l_leg_kny", "l_uleg", "l_lleg", (0, 0, -0.42), "y", 0.0, 2.35, 12, 890, 3000, 60),
    ("l_leg_aky", "l_lleg", "l_talus", (0, 0, -0.42), "y", -1.0, 0.7, 12, 740, 1500, 30),
    ("l_leg_akx", "l_talus", "l_foot", (0, 0, 0), "x", -0.8, 0.8, 12, 360, 1000, 20),
    ("l_arm_shz", "utorso", "l_clav", (0, 0.2, 0.3), "z", -1.57, 0.79, 12, 87, 1000, 40),
    ("l_arm_shx", "l_clav", "l_scap", (0, 0.1, 0), "x", -1.57, 1.57, 12, 99, 1000, 40),
    ("l_arm_ely", "l_scap", "l_uarm", (0, 0.05, 0), "y", -3.14, 3.14, 12, 63, 600, 20),
    ("l_arm_elx", "l_uarm", "l_larm", (0, 0.33, 0), "x", 0.0, 2.35, 12, 112, 600, 20),
    ("l_arm_wry", "l_larm", "l_ufarm", (0, 0.28, 0), "y", -3.14, 3.14, 12, 25, 150, 3),
    ("l_arm_wrx", "l_ufarm", "l_hand", (0, 0.03, 0), "x", -1.18, 1.18, 12, 25, 150, 3),
    ("l_gripper", "l_hand", "l_finger", (0, 0.1, -0.04), "z", 0.0, 0.04, 0.5, 20, 2000, 20),
]
# Joints whose limits are not symmetric about zero swap and negate them on the right side.
_MIRRORED_LIMITS = ("l_leg_hpz", "l_arm_shz", "l_arm_elx")


def _spec(row: Row) -> JointSpec:
    name, parent, child, xyz, axis, lower, upper, velocity, effort, kp, kd = row
    return JointSpec(name, parent, child, xyz, AXES[axis], lower, upper, velocity, effort, kp, kd)


def _right(row: Row) -> Row:
    name, parent, child, xyz, axis, lower, upper, *rest = row
    if name in _MIRRORED_LIMITS:
        lower, upper = -upper, -lower

    def flip(link: str) -> str:
        return "r_" + link[2:] if link.startswith("l_") else link

    return (
        flip(name),
        flip(parent),
        flip(child),
        (xyz[0], -xyz[1], xyz[2]),
        axis,
        lower,
        upper,
        *rest,
    )


_ROWS = _TRUNK + [r for r in _LEFT_LIMBS if "_leg_" in r[0]]
_ROWS += [_right(r) for r in _LEFT_LIMBS if "_leg_" in r[0]]
_ROWS += [r for r in _LEFT_LIMBS if "_arm_" in r[0]]
_ROWS += [_right(r) for r in _LEFT_LIMBS if "_arm_" in r[0]]
BODY_JOINTS: list[JointSpec] = [_spec(row) for row in _ROWS]
GRIPPER_JOINTS: list[JointSpec] = [_spec(_LEFT_LIMBS[-1]), _spec(_right(_LEFT_LIMBS[-1]))]
ALL_JOINTS: list[JointSpec] = BODY_JOINTS + GRIPPER_JOINTS
JOINT_NAMES: list[str] = [spec.name for spec in ALL_JOINTS]
HAND_LINKS = {"left": "l_hand", "right": "r_hand"}
FINGER_LINKS = {"left": "l_finger", "right": "r_finger"}
HEAD_LINK = "head"

# Knees slightly bent, arms down: the posture the stand behaviour holds.
STAND_POSTURE: dict[str, float] = {
    "l_leg_hpy": -0.3,
    "l_leg_kny": 0.6,
    "l_leg_aky": -0.3,
    "r_leg_hpy": -0.3,
    "r_leg_kny": 0.6,
    "r_leg_aky": -0.3,
    "l_arm_shx": -1.3,
    "r_arm_shx": 1.3,
    "l_arm_elx": 0.3,
    "r_arm_elx": -0.3,
}
SIT_POSTURE: dict[str, float] = {
    "l_leg_hpy": -1.5,
    "l_leg_kny": 1.5,
    "r_leg_hpy": -1.5,
    "r_leg_kny": 1.5,
    "l_arm_shx": -0.6,
    "r_arm_shx": 0.6,
    "l_arm_shz": -1.0,
    "r_arm_shz": 1.0,
    "l_arm_elx": 1.2,
    "r_arm_elx": -1.2,
}
# Pelvis height above the ground in STAND_POSTURE (hip offset + legs + ankle + sole).
STAND_PELVIS_HEIGHT = 0.05 + 2 * 0.42 * math.cos(0.3) + 0.085
GRASP_POINT_IN_HAND: Vec3 = (0.0, 0.12, 0.0)

# Link masses (kg), after Atlas v5's distribution (lighter arms); about 145 kg in all.
_MASSES = {
    "pelvis": 17.9,
    "ltorso": 2.4,
    "mtorso": 0.7,
    "utorso": 52.0,
    "head": 6.0,
    "uglut": 1.9,
    "lglut": 0.9,
    "uleg": 9.2,
    "lleg": 5.5,
    "talus": 0.13,
    "foot": 2.4,
    "clav": 3.0,
    "scap": 2.5,
    "uarm": 2.0,
    "larm": 1.8,
    "ufarm": 0.8,
    "hand": 1.2,
    "finger": 0.2,
}
DARK = (0.2, 0.2, 0.25, 1.0)
LIGHT = (0.75, 0.75, 0.8, 1.0)


def _link(name: str) -> Link:
    """Return the link named `name` with its mass and shapes."""
    side = name[:2] if name[:2] in ("l_", "r_") else ""
    part = name[len(side) :]
    s = -1.0 if side == "r_" else 1.0
    mass = _MASSES[part]
    shapes = {
        "pelvis": [box(0.2, 0.3, 0.15)],
        "utorso": [box(0.35, 0.45, 0.5, xyz=(0, 0, 0.25))],
        "head": [box(0.16, 0.16, 0.16, xyz=(0.05, 0, 0.08))],
        "uleg": [capsule(0.07, 0.28, xyz=(0, 0, -0.21))],
        "lleg": [capsule(0.06, 0.3, xyz=(0, 0, -0.21))],
        "foot": [box(0.26, 0.13, 0.05, xyz=(0.04, 0, -0.06))],
        "uarm": [capsule(0.05, 0.22, xyz=(0, s * 0.165, 0), rpy=(HALF_PI, 0, 0))],
        "larm": [capsule(0.045, 0.18, xyz=(0, s * 0.14, 0), rpy=(HALF_PI, 0, 0))],
        "hand": [box(0.08, 0.1, 0.08, xyz=(0, s * 0.08, 0))],
        "finger": [box(0.06, 0.04, 0.02, xyz=(0, 0, 0))],
    }.get(part, [sphere(0.03)])
    collide = part in (
        "pelvis",
        "utorso",
        "head",
        "uleg",
        "lleg",
        "foot",
        "uarm",
        "larm",
        "hand",
        "finger",
    )
    com = (0.0, s * GRASP_POINT_IN_HAND[1], 0.0) if part == "hand" else None
    return Link(
        name, mass, shapes, rgba=DARK if part == "foot" else LIGHT, collide=collide, com=com
    )


def build_humanoid() -> Robot:
    """Return the humanoid's URDF model."""
    robot = Robot("drc_humanoid")
    robot.add(_link("pelvis"))
    for spec in ALL_JOINTS:
        kind = "prismatic" if spec.name.endswith("gripper") else "revolute"
        joint = Joint(
            spec.name,
            kind,
            spec.parent,
            spec.child,
            xyz=spec.xyz,
            axis=spec.axis,
            lower=spec.lower,
            upper=spec.upper,
            velocity=spec.velocity,
            effort=spec.effort,
            damping=0.1,
        )
        robot.add(_link(spec.child), joint)
    return robot
