"""Rims and levers a hand turns: grasp (the grasp joint), move along the arc by arm IK, re-grasp.

The valve wheel, the steering wheel, the hand brake and the F/N/R switch are revolute joints
with friction. Nothing turns them but a hand that holds them (a point-to-point grasp joint,
made only when the closed hand is at the rim or the lever's end) and the arm's joints, driven
by the reach IK towards a point just ahead along the arc about the joint's axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drcsim._bullet import pybullet
from drcsim.assists import HANDLE_REACH, Grasps
from drcsim.control import JointController
from drcsim.reach import REACH_EVERY, Reach
from drcsim.scene import Scene

LEAD = 0.12  # rad the arc target runs ahead of the hand
TOLERANCE = 0.04  # rad: close enough to the target angle
APPROACH_LIMIT = 4 * 50  # IK updates (50 Hz) a hand may take to reach the rim
STALL_UPDATES = 50  # IK updates without progress before a stroke counts as stalled
Vector = tuple[float, float, float]


@dataclass(frozen=True)
class Handle:
    """Where a hand holds a revolute joint: anywhere on a rim, or at a lever's end."""

    name: str
    body: int
    joint: int  # pybullet's joint index, which is also the child link's index
    axis: Vector  # the joint axis in the link frame
    u: Vector  # angle 0 in the link frame, perpendicular to the axis
    radius: float
    rim: bool  # a wheel (held anywhere on the circle) or a lever (held at its end)
    carried: bool = False  # the hand pivots on it (assists.Grasps), never carries it

    def angle(self, scene: Scene) -> float:
        """Return the joint's real angle."""
        return float(scene.client.getJointState(self.body, self.joint)[0])

    def _frame(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        state = scene.client.getLinkState(self.body, self.joint, computeForwardKinematics=True)
        rotation = np.array(scene.client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]), rotation

    def between_jaws(self, scene: Scene, closing: object) -> bool:
        """Return True: a hand at the rim or the lever's end pivots on it, however it closes."""
        return True

    def point(self, scene: Scene, phi: float) -> np.ndarray:
        """Return the world point of the grip at angle `phi` of the fixed parent's frame."""
        origin, rotation = self._frame(scene)
        local = phi - self.angle(scene) if self.rim else 0.0
        u, axis = np.array(self.u), np.array(self.axis)
        v = np.cross(axis, u)
        return origin + rotation @ (self.radius * (math.cos(local) * u + math.sin(local) * v))

    def locate(self, scene: Scene, world: np.ndarray) -> tuple[float, float]:
        """Return the parent-frame angle of `world` about the axis and its distance to the grip."""
        origin, rotation = self._frame(scene)
        q = rotation.T @ (world - origin)
        u, axis = np.array(self.u), np.array(self.axis)
        v = np.cross(axis, u)
        local = math.atan2(float(q @ v), float(q @ u))
        if not self.rim:
            return self.angle(scene), float(np.linalg.norm(q - self.radius * u))
        axial = float(q @ axis)
        radial = math.hypot(float(q @ u), float(q @ v))
        return local + self.angle(scene), math.hypot(radial - self.radius, axial)

    def turned(self, scene: Scene, world: np.ndarray, delta: float) -> np.ndarray:
        """Return `world` turned by `delta` rad about the joint's axis."""
        origin, rotation = self._frame(scene)
        k = rotation @ np.array(self.axis)
        p = world - origin
        c, s = math.cos(delta), math.sin(delta)
        return origin + p * c + np.cross(k, p) * s + k * float(k @ p) * (1 - c)


def set_friction(scene: Scene, handle: Handle, torque: float) -> None:
    """Give a handle's joint dry friction (a velocity motor at rest with a small force)."""
    scene.client.setJointMotorControl2(
        handle.body, handle.joint, pybullet.VELOCITY_CONTROL, targetVelocity=0.0, force=torque
    )


class Turner:
    """Turns one handle to a target angle with one arm, re-grasping in strokes on a rim."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        grasps: Grasps,
        handle: Handle,
        side: str,
        home: float = 0.0,
        stroke: float = math.inf,
    ) -> None:
        self.scene, self.grasps, self.handle, self.side = scene, grasps, handle, side
        self.home, self.stroke = home, stroke
        self.goal = handle.angle(scene)
        self.reach = Reach(scene, controller, side, list(grasps.palm(side)), False, grasps)
        self.grip_at = home  # the parent-frame angle the hand goes to when not holding
        self.updates = 0  # IK updates in the current approach or stroke
        self.best = 0.0  # the angle at the last progress
        self.stalls = 0
        self.status = "approaching"
        if grasps.held.get(side, (0, ""))[1] == handle.name:
            self.status = "holding"

    def holding(self) -> bool:
        """Return whether the hand holds this handle now."""
        return self.grasps.held.get(self.side, (0, ""))[1] == self.handle.name

    def done(self) -> bool:
        """Return whether the handle is at its goal."""
        return abs(self.goal - self.handle.angle(self.scene)) <= TOLERANCE

    def let_go(self) -> None:
        """Open the hand if it holds this handle."""
        if self.holding():
            self.grasps.open(self.side)

    def apply(self, step: int) -> str:
        """Run this physics step's share (IK at 50 Hz); return the status."""
        if step % REACH_EVERY == 0 and not self.status.startswith("stalled"):
            self._update()
            self.reach.update()
        self.reach.apply()
        return self.status

    def _update(self) -> None:
        scene, handle = self.scene, self.handle
        palm = np.array(self.grasps.palm(self.side))
        self.updates += 1
        if not self.holding():
            self._approach(palm)
            return
        angle = handle.angle(scene)
        remaining = self.goal - angle
        if abs(remaining) <= TOLERANCE:
            self.reach.target = palm  # hold it where it is
            self.status, self.updates = "holding", 0
            return
        direction = math.copysign(1.0, remaining)
        phi, _ = handle.locate(scene, palm)
        phi = self.home + math.remainder(phi - self.home, 2 * math.pi)
        room = (self.home + direction * self.stroke - phi) * direction  # left in this stroke
        if handle.rim and room < 0.02:
            self._regrasp(direction, "end of the stroke", stalled=False)
            return
        if abs(angle - self.best) > 0.02:
            self.best, self.updates = angle, 0
        elif self.updates > STALL_UPDATES:
            self._regrasp(direction, "the arm cannot follow the rim", stalled=True)
            return
        delta = direction * min(abs(remaining), LEAD, max(room, 0.0))
        self.reach.target = handle.turned(scene, palm, delta)
        self.status = "turning"

    def _approach(self, palm: np.ndarray) -> None:
        grip = self.handle.point(self.scene, self.grip_at)
        self.reach.target = grip
        self.status = "approaching"
        _, distance = self.handle.locate(self.scene, palm)
        if np.linalg.norm(grip - palm) < 0.03 and distance <= HANDLE_REACH:
            if self.grasps.close(self.side) == self.handle.name:
                self.status, self.updates = "holding", 0
                self.best = self.handle.angle(self.scene)
                return
            self.grasps.open(self.side)
        if self.updates > APPROACH_LIMIT:
            self.status = f"stalled: the {self.side} hand cannot reach the {self.handle.name}"

    def _regrasp(self, direction: float, why: str, stalled: bool) -> None:
        """Let go and take the rim again at a stroke's start (twice without progress: stall)."""
        angle = self.handle.angle(self.scene)
        self.stalls = self.stalls + 1 if stalled else 0
        self.grasps.open(self.side)
        if self.stalls >= 2 or not self.handle.rim:
            self.status = f"stalled: {why} ({self.handle.name} at {angle:.2f} rad)"
            return
        self.best, self.updates = angle, 0
        self.grip_at = self.home - direction * 0.8 * self.stroke
        self.status = "approaching"
