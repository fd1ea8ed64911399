"""Walking pattern maths: ZMP preview control on the cart-table model, footsteps, leg IK.

Pure functions and small classes with no pybullet in them (Kajita et al., "Biped walking
pattern generation by using preview control of zero-moment point", ICRA 2003; the analytic
6-DoF leg inverse kinematics of Kajita's "Introduction to Humanoid Robotics").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import numpy as np

GRAVITY = 9.81
PREVIEW_DT = 0.01  # s: the pattern generator runs at 100 Hz
PREVIEW_S = 1.6  # s of future ZMP reference the controller looks at
THIGH = 0.42
SHIN = 0.42
HIP_OFFSET = (0.0, 0.09, -0.05)  # left hip joint in the pelvis frame (right: y mirrored)
ANKLE_TO_SOLE = 0.085
ZMP_INWARD = 0.03  # m: the ZMP reference sits this far inboard of the ankle...
ZMP_AHEAD = 0.02  # ...and this far ahead of it, mid-sole
START_S = 0.6  # s to shift onto the first stance foot, and to settle at the end


@cache
def preview_gains(com_height: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Return (A, B, Gi, Gx, Gd...) of the optimal ZMP preview servo for a COM height."""
    dt = PREVIEW_DT
    a = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    b = np.array([[dt**3 / 6], [dt * dt / 2], [dt]])
    c = np.array([[1.0, 0.0, -com_height / GRAVITY]])
    # Augmented system with the integral of the ZMP error (Katayama's preview servo).
    a1 = np.block([[np.eye(1), c @ a], [np.zeros((3, 1)), a]])
    b1 = np.vstack([c @ b, b])
    q = np.diag([1.0, 0.0, 0.0, 0.0])
    r = np.array([[1e-6]])
    p = q.copy()
    for _ in range(2000):  # the discrete Riccati equation, by iteration
        gain = np.linalg.solve(r + b1.T @ p @ b1, b1.T @ p @ a1)
        nxt = a1.T @ p @ a1 - a1.T @ p @ b1 @ gain + q
        if np.max(np.abs(nxt - p)) < 1e-12:
            p = nxt
            break
        p = nxt
    inv = np.linalg.inv(r + b1.T @ p @ b1)
    k = inv @ b1.T @ p @ a1
    gi, gx = float(k[0, 0]), k[:, 1:].reshape(3)
    ac = a1 - b1 @ k
    steps = round(PREVIEW_S / dt)
    gd = np.zeros(steps)
    x = -ac.T @ p @ np.array([[1.0], [0.0], [0.0], [0.0]])
    gd[0] = -gi
    for j in range(1, steps):
        gd[j] = float((inv @ b1.T @ x)[0, 0])
        x = ac.T @ x
    return a, b.reshape(3), gi, np.concatenate([gx, gd])


class PreviewAxis:
    """One horizontal axis of the COM: state [c, c', c''] driven by the ZMP preview servo."""

    def __init__(self, com_height: float, start: float) -> None:
        self.a, self.b, self.gi, gains = preview_gains(round(com_height, 3))
        self.gx, self.gd = gains[:3], gains[3:]
        self.c = np.array([start, 0.0, 0.0])
        self.error = 0.0
        self.com_height = com_height

    def step(self, future_zmp: np.ndarray) -> float:
        """Advance 10 ms given the ZMP reference from now on; return the COM position."""
        zmp = self.c[0] - self.com_height / GRAVITY * self.c[2]
        self.error += zmp - future_zmp[0]
        # Relative to the current reference: with a finite preview the gains' sum is not
        # exactly zero, and absolute coordinates would bias the COM by metres walked.
        origin = float(future_zmp[0])
        relative = self.c - np.array([origin, 0.0, 0.0])
        u = (
            -self.gi * self.error
            - float(self.gx @ relative)
            - float(self.gd @ (future_zmp - origin))
        )
        self.c = self.a @ self.c + self.b * u
        return float(self.c[0])


@dataclass(frozen=True)
class Foothold:
    """Where a foot stands: sole centre (x, y, z) and yaw, in the world frame."""

    x: float
    y: float
    z: float
    yaw: float


# Moves a plan's footholds: given the feet and every step's side and foothold, where each goes.
Placer = Callable[[dict[str, Foothold], list[tuple[str, Foothold]]], list[Foothold]]


def wrap_angle(angle: float) -> float:
    """Return `angle` wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def plan_poses(
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    step_length: float,
    turn_per_step: float = 0.35,
) -> list[tuple[float, float, float]]:
    """Return pelvis waypoints (x, y, yaw), one per step: turn to face, walk, turn to yaw."""
    x, y, yaw = start
    gx, gy, gyaw = goal
    poses: list[tuple[float, float, float]] = []
    distance = math.hypot(gx - x, gy - y)
    if distance > 0.05:
        heading = math.atan2(gy - y, gx - x)
        # Short moves sideways or backwards are stepped without turning round.
        if distance < 0.6 and abs(wrap_angle(heading - yaw)) > 0.6:
            heading = yaw
        while abs(wrap_angle(heading - yaw)) > 1e-3:
            yaw = yaw + max(-turn_per_step, min(turn_per_step, wrap_angle(heading - yaw)))
            poses.append((x, y, yaw))
        count = max(1, math.ceil(distance / step_length))
        for i in range(1, count + 1):
            poses.append((x + (gx - x) * i / count, y + (gy - y) * i / count, yaw))
        x, y = gx, gy
    while abs(wrap_angle(gyaw - yaw)) > 1e-3:
        yaw = yaw + max(-turn_per_step, min(turn_per_step, wrap_angle(gyaw - yaw)))
        poses.append((x, y, yaw))
    return poses


def rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Return the rotation matrix Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def leg_ik(
    hip: np.ndarray, body: np.ndarray, ankle: np.ndarray, foot: np.ndarray
) -> tuple[float, float, float, float, float, float]:
    """Return (hpz, hpx, hpy, kny, aky, akx) placing the ankle at `ankle` with rotation `foot`.

    `hip` is the hip joint's world position, `body` the pelvis rotation, `foot` the foot's.
    """
    r = foot.T @ (hip - ankle)
    length = float(np.linalg.norm(r))
    reach = THIGH + SHIN - 1e-4
    if length > reach:  # out of reach: stretch as far as possible along the same line
        r, length = r * (reach / length), reach
    cos_knee = (THIGH**2 + SHIN**2 - length**2) / (2 * THIGH * SHIN)
    knee = math.pi - math.acos(max(-1.0, min(1.0, cos_knee)))
    alpha = math.asin(max(-1.0, min(1.0, THIGH * math.sin(math.pi - knee) / length)))
    akx = math.atan2(r[1], r[2])
    aky = -math.atan2(r[0], math.copysign(math.hypot(r[1], r[2]), r[2])) - alpha
    rest = body.T @ foot @ rotation(-akx, 0.0, 0.0) @ rotation(0.0, -knee - aky, 0.0)
    hpz = math.atan2(-rest[0, 1], rest[1, 1])
    cz, sz = math.cos(hpz), math.sin(hpz)
    hpx = math.atan2(rest[2, 1], -rest[0, 1] * sz + rest[1, 1] * cz)
    hpy = math.atan2(-rest[2, 0], rest[2, 2])
    return hpz, hpx, hpy, knee, aky, akx


@dataclass
class GaitParameters:
    """What a team tunes: step length and height, speed (step time), stance width."""

    step_length: float = 0.25  # m per step
    step_height: float = 0.06  # m of swing-foot clearance
    step_time: float = 0.6  # s of single support per step (shorter: faster)
    double_support: float = 0.3  # s with both feet down between steps
    stance_width: float = 0.18  # m between the ankles
    pelvis_height: float = 0.89  # m above the feet

    def checked(self) -> GaitParameters:
        """Return the parameters; raise ValueError for one the legs cannot do.

        The command channel refuses a team's value outside these ranges (protocol.RANGES)
        before it gets here; this guards the walker's own callers.
        """
        for name, low, high in _GAIT_RANGES:
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"{name} must be in {low:g}..{high:g}, not {value:g}")
        return self


_GAIT_RANGES = (
    ("step_length", 0.02, 0.5),
    ("step_height", 0.01, 0.2),
    ("step_time", 0.3, 2.0),
    ("double_support", 0.05, 1.0),
    ("stance_width", 0.12, 0.4),
    ("pelvis_height", 0.75, 0.93),
)


@dataclass
class Swing:
    """One step: which foot moves, from where to where, during which ticks."""

    side: str
    start: Foothold
    end: Foothold
    first: int
    last: int
    floor: tuple[float, ...] = ()  # lowest the sole may pass, at 0, 0.1, .. 1 of the way
    touched: Foothold | None = None  # where it touched down above the planned ground, if so


def _hold(
    side: str,
    pose: tuple[float, float, float],
    width: float,
    ground: Callable[[float, float], float],
) -> Foothold:
    x, y, yaw = pose
    lateral = width / 2 * (1 if side == "left" else -1)
    fx, fy = x - math.sin(yaw) * lateral, y + math.cos(yaw) * lateral
    return Foothold(fx, fy, ground(fx, fy), yaw)


def zmp_point(foot: Foothold, side: str) -> tuple[float, float]:
    """Return the ZMP reference under a foot: mid-sole, a little inboard (margin to roll)."""
    inward = ZMP_INWARD * (-1.0 if side == "left" else 1.0)
    c, s = math.cos(foot.yaw), math.sin(foot.yaw)
    return foot.x + c * ZMP_AHEAD - s * inward, foot.y + s * ZMP_AHEAD + c * inward


def _ramp(
    zmp: list[tuple[float, float]], a: tuple[float, float], b: tuple[float, float], ticks: int
) -> None:
    for i in range(1, ticks + 1):
        s = i / ticks
        zmp.append((a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s))


def timeline(
    feet: dict[str, Foothold],
    poses: list[tuple[float, float, float]],
    p: GaitParameters,
    start: tuple[float, float],
    ground: Callable[[float, float], float],
    place: Placer | None = None,
) -> tuple[list[tuple[float, float]], list[Swing]]:
    """Return the 100 Hz ZMP reference and the swings that take the feet through `poses`.

    `place` may move the planned footholds (given the feet and every step's side and
    foothold, it returns where each step really goes).
    """
    ss, ds = round(p.step_time / PREVIEW_DT), round(p.double_support / PREVIEW_DT)
    zmp: list[tuple[float, float]] = []
    swings: list[Swing] = []
    feet = dict(feet)
    mid_yaw = math.atan2(
        sum(math.sin(f.yaw) for f in feet.values()), sum(math.cos(f.yaw) for f in feet.values())
    )
    first_side = "left" if poses and poses[0][2] - mid_yaw > 1e-3 else "right"
    other = "right" if first_side == "left" else "left"
    # Shift onto the first stance foot, then step; the last step brings the feet together.
    _ramp(
        zmp,
        start,
        zmp_point(feet[other], other),
        round(max(START_S, p.double_support) / PREVIEW_DT),
    )
    moves = [(pose, (first_side, other)[i % 2]) for i, pose in enumerate(poses)]
    if poses:
        moves.append((poses[-1], "left" if moves[-1][1] == "right" else "right"))
    steps = [(moving, _hold(moving, pose, p.stance_width, ground)) for pose, moving in moves]
    ends = [end for _, end in steps] if place is None else place(feet, steps)
    for (moving, _), end in zip(steps, ends, strict=True):
        stance = "right" if moving == "left" else "left"
        first = len(zmp)
        zmp.extend([zmp_point(feet[stance], stance)] * ss)
        swings.append(Swing(moving, feet[moving], end, first, len(zmp)))
        feet[moving] = end
        _ramp(zmp, zmp_point(feet[stance], stance), zmp_point(end, moving), ds)
    # The last steps end between the feet, where the walker then stands.
    middle = ((feet["left"].x + feet["right"].x) / 2, (feet["left"].y + feet["right"].y) / 2)
    _ramp(zmp, zmp[-1] if zmp else start, middle, round(START_S / PREVIEW_DT))
    return zmp, swings
