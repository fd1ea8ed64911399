"""The spinning lidar sees out of the head, not into it, and sees the robot's own hands."""

from __future__ import annotations

import math

import numpy as np
from drcsim.models import humanoid
from drcsim.sensors import LIDAR_IN_HEAD


def _ranges(sim, spindle: float) -> np.ndarray:
    message = sim.sensors.compute("lidar", spindle / sim.sensors.settings.lidar_spin)
    assert math.isclose(message["spindle"], spindle % (2 * math.pi), abs_tol=1e-6)
    return np.frombuffer(message["ranges"], dtype=np.float32)


def test_no_beam_starts_inside_the_head_and_none_returns_nearer_than_the_minimum(
    make_sim,
) -> None:
    sim = make_sim("vrc_task_2", "1")
    client, robot = sim.scene.client, sim.scene.robot
    head = sim.scene.robot_links[humanoid.HEAD_LINK]
    (shape,) = client.getCollisionShapeData(robot, head)
    half = np.array(shape[3]) / 2  # the head's box, centred on the head frame
    assert shape[2] == 3 and shape[5] == (0.0, 0.0, 0.0)
    origin, rotation = sim.sensors._head_pose()
    minimum = sim.sensors.settings.lidar_min_range
    assert minimum == 0.1  # the Hokuyo UTM-30LX's: it measures nothing nearer
    for spindle in (math.pi / 2, 3 * math.pi / 2, 0.0):  # both vertical planes, horizontal
        starts, _ = sim.sensors._lidar_rays(spindle)
        in_head = (starts - origin) @ rotation  # rows: each start in the head frame
        assert np.all(np.any(np.abs(in_head) > half, axis=1))
        from_sensor = np.linalg.norm(in_head - LIDAR_IN_HEAD, axis=1)
        assert np.allclose(from_sensor, minimum)
        ranges = _ranges(sim, spindle)
        assert len(ranges) == 1081 and ranges.min() >= np.float32(minimum)


def test_a_hand_raised_in_front_of_the_sensor_is_seen(make_sim) -> None:
    sim = make_sim("vrc_task_2", "1")
    client, robot, links = sim.scene.client, sim.scene.robot, sim.scene.robot_links
    joints = {
        client.getJointInfo(robot, j)[1].decode(): j for j in range(client.getNumJoints(robot))
    }
    origin, rotation = sim.sensors._head_pose()
    sensor = origin + rotation @ LIDAR_IN_HEAD
    before = {}
    for name, angle in (("l_arm_shz", -1.57), ("l_arm_shx", 0.5), ("l_arm_elx", 0.0)):
        before[name] = client.getJointState(robot, joints[name])[0]
        client.resetJointState(robot, joints[name], angle)  # the arm forward, at head height
    state = client.getLinkState(robot, links["l_hand"], computeForwardKinematics=True)
    hand = rotation.T @ (np.array(state[0]) - sensor)  # in the head frame, from the sensor
    assert hand[0] > 0.3
    spindle = math.atan2(hand[2], hand[1])  # the scan plane through the hand
    beam = int(
        np.argmin(np.abs(sim.sensors.lidar_angles - math.atan2(math.hypot(*hand[1:]), hand[0])))
    )
    seen = _ranges(sim, spindle)[beam - 3 : beam + 4]
    for name, angle in before.items():
        client.resetJointState(robot, joints[name], angle)
    unseen = _ranges(sim, spindle)[beam - 3 : beam + 4]
    assert np.all(seen < np.linalg.norm(hand) + 0.1) and np.all(unseen > 1.0)
