"""The reach behaviour: one hand (or the object it holds) to a point, by task-space IK."""

from __future__ import annotations

import numpy as np

from drcsim.assists import Grasps
from drcsim.control import JointController
from drcsim.models import humanoid
from drcsim.scene import Scene

REACH_EVERY = 20  # physics steps between task-space IK updates (50 Hz)
REACH_GAIN = 0.3
REACH_TOLERANCE = 0.02
ARM_JOINTS = {
    side: [s.name for s in humanoid.BODY_JOINTS if s.name.startswith(f"{side[0]}_arm")]
    for side in ("left", "right")
}


class Reach:
    """Moves one hand (or the object it holds) to a world point by task-space integral IK."""

    def __init__(
        self,
        scene: Scene,
        controller: JointController,
        side: str,
        target: list[float],
        tool: bool,
        grasps: Grasps,
        frame: str = "world",
    ) -> None:
        self.scene, self.controller, self.side = scene, controller, side
        self.target = np.array(target, dtype=float)
        self.frame = frame
        self.link = scene.robot_links[humanoid.HAND_LINKS[side]]
        self.slots = np.array([controller.slot[name] for name in ARM_JOINTS[side]])
        self.joint_targets = controller.position[self.slots].copy()
        client = scene.client
        # Points are kept in the hand's URDF link frame: calculateJacobian works in that frame.
        link_state = client.getLinkState(scene.robot, self.link)
        self.local = list(link_state[2])  # the palm (the hand link's centre of mass)
        self.status = "reaching"
        if tool and grasps.holding("hose") == side and scene.hose is not None:
            frame_pos, frame_orn = link_state[4], link_state[5]
            obj_pos, _ = client.getBasePositionAndOrientation(scene.hose)
            inv_pos, inv_orn = client.invertTransform(frame_pos, frame_orn)
            self.local = list(client.multiplyTransforms(inv_pos, inv_orn, obj_pos, [0, 0, 0, 1])[0])

    def point(self) -> np.ndarray:
        """Return the world position of the point being moved."""
        client = self.scene.client
        state = client.getLinkState(self.scene.robot, self.link)
        return np.array(client.multiplyTransforms(state[4], state[5], self.local, [0, 0, 0, 1])[0])

    def update(self) -> None:
        """One IK iteration from the measured error; the joint PIDs do the rest."""
        client, controller = self.scene.client, self.controller
        target = self.target
        if self.frame == "pelvis":
            pos, orn = client.getBasePositionAndOrientation(self.scene.robot)
            target = np.array(client.multiplyTransforms(pos, orn, target.tolist(), [0, 0, 0, 1])[0])
        error = target - self.point()
        self.status = "reached" if np.linalg.norm(error) < REACH_TOLERANCE else "reaching"
        positions = [0.0] * client.getNumJoints(self.scene.robot)
        for slot, index in enumerate(controller.indices):
            positions[index] = float(controller.position[slot])
        zeros = [0.0] * len(positions)
        linear, _ = client.calculateJacobian(
            self.scene.robot, self.link, self.local, positions, zeros, zeros
        )
        # pybullet returns a floating base's Jacobian in the base frame: rotate it to world.
        _, base_orn = client.getBasePositionAndOrientation(self.scene.robot)
        jacobian = np.array(client.getMatrixFromQuaternion(base_orn)).reshape(3, 3) @ np.array(
            linear
        )
        offset = jacobian.shape[1] - len(positions)  # a floating base adds 6 columns first
        columns = [offset + controller.indices[slot] for slot in self.slots]
        arm = jacobian[:, columns]
        damping = 0.05**2 * np.eye(3)
        step = arm.T @ np.linalg.solve(arm @ arm.T + damping, error)
        step = np.clip(REACH_GAIN * step, -0.15, 0.15)
        lower, upper = controller.lower[self.slots], controller.upper[self.slots]
        self.joint_targets = np.clip(self.joint_targets + step, lower, upper)

    def apply(self) -> None:
        """Hold the arm's joint targets."""
        self.controller.set_slot_positions(self.slots, self.joint_targets)
