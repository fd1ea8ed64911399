"""An Atlas-like humanoid: Atlas v5's 28-DoF joint names, limits and masses, plus grippers."""

from __future__ import annotations

import math
from dataclasses import dataclass

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


def _leg(side: str) -> list[JointSpec]:
    s = 1.0 if side == "l" else -1.0
    hpz = (-0.174, 0.786) if side == "l" else (-0.786, 0.174)
    return [
        JointSpec(
            f"{side}_leg_hpz",
            "pelvis",
            f"{side}_uglut",
            (0, s * 0.09, -0.05),
            Z,
            *hpz,
            12,
            275,
            1500,
            30,
        ),
        JointSpec(
            f"{side}_leg_hpx",
            f"{side}_uglut",
            f"{side}_lglut",
            (0, 0, 0),
            X,
            -0.523,
            0.523,
            12,
            530,
            3000,
            60,
        ),
        JointSpec(
            f"{side}_leg_hpy",
            f"{side}_lglut",
            f"{side}_uleg",
            (0, 0, 0),
            Y,
            -1.61,
            0.65,
            12,
            840,
            3000,
            60,
        ),
        JointSpec(
            f"{side}_leg_kny",
            f"{side}_uleg",
            f"{side}_lleg",
            (0, 0, -0.42),
            Y,
            0.0,
            2.35,
            12,
            890,
            3000,
            60,
        ),
        JointSpec(
            f"{side}_leg_aky",
            f"{side}_lleg",
            f"{side}_talus",
            (0, 0, -0.42),
            Y,
            -1.0,
            0.7,
            12,
            740,
            1500,
            30,
        ),
        JointSpec(
            f"{side}_leg_akx",
            f"{side}_talus",
            f"{side}_foot",
            (0, 0, 0),
            X,
            -0.8,
            0.8,
            12,
            360,
            1000,
            20,
        ),
    ]


def _arm(side: str) -> list[JointSpec]:
    s = 1.0 if side == "l" else -1.0
    shz = (-1.57, 0.79) if side == "l" else (-0.79, 1.57)
    elx = (0.0, 2.35) if side == "l" else (-2.35, 0.0)
    return [
        JointSpec(
            f"{side}_arm_shz", "utorso", f"{side}_clav", (0, s * 0.2, 0.3), Z, *shz, 12, 87, 400, 10
        ),
        JointSpec(
            f"{side}_arm_shx",
            f"{side}_clav",
            f"{side}_scap",
            (0, s * 0.1, 0),
            X,
            -1.57,
            1.57,
            12,
            99,
            400,
            10,
        ),
        JointSpec(
            f"{side}_arm_ely",
            f"{side}_scap",
            f"{side}_uarm",
            (0, s * 0.05, 0),
            Y,
            -3.14,
            3.14,
            12,
            63,
            250,
            6,
        ),
        JointSpec(
            f"{side}_arm_elx",
            f"{side}_uarm",
            f"{side}_larm",
            (0, s * 0.33, 0),
            X,
            *elx,
            12,
            112,
            250,
            6,
        ),
        JointSpec(
            f"{side}_arm_wry",
            f"{side}_larm",
            f"{side}_ufarm",
            (0, s * 0.28, 0),
            Y,
            -3.14,
            3.14,
            12,
            25,
            60,
            1.5,
        ),
        JointSpec(
            f"{side}_arm_wrx",
            f"{side}_ufarm",
            f"{side}_hand",
            (0, s * 0.03, 0),
            X,
            -1.18,
            1.18,
            12,
            25,
            60,
            1.5,
        ),
    ]


BODY_JOINTS: list[JointSpec] = [
    JointSpec(
        "back_bkz", "pelvis", "ltorso", (-0.0125, 0, 0.09), Z, -0.663, 0.663, 12, 106, 1500, 40
    ),
    JointSpec("back_bky", "ltorso", "mtorso", (0, 0, 0.162), Y, -0.219, 0.538, 9, 445, 3000, 60),
    JointSpec("back_bkx", "mtorso", "utorso", (0, 0, 0.05), X, -0.523, 0.523, 12, 300, 3000, 60),
    JointSpec("neck_ry", "utorso", "head", (0.1, 0, 0.55), Y, -0.602, 1.145, 6.28, 25, 80, 2),
    *_leg("l"),
    *_leg("r"),
    *_arm("l"),
    *_arm("r"),
]

GRIPPER_JOINTS: list[JointSpec] = [
    JointSpec(
        f"{side}_gripper",
        f"{side}_hand",
        f"{side}_finger",
        (0, s * 0.1, -0.04),
        Z,
        0.0,
        0.04,
        0.2,
        60,
        2000,
        20,
    )
    for side, s in (("l", 1.0), ("r", -1.0))
]

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

# Link masses (kg), following Atlas v5's distribution; 157 kg in all.
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
    "clav": 4.5,
    "scap": 3.9,
    "uarm": 2.4,
    "larm": 3.4,
    "ufarm": 2.3,
    "hand": 2.1,
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
