"""Joint control: limits are enforced whatever the command, on the client's own world."""

from __future__ import annotations

import numpy as np
import pytest
from drcsim._bullet import new_client, pybullet
from drcsim.errors import ProtocolError
from drcsim.protocol import check_command


def test_position_targets_beyond_limits_are_refused_with_the_range(make_sim) -> None:
    sim = make_sim("vrc_task_2")
    c = sim.controller
    # Arm joints: the stand behaviour owns the legs and back.
    wanted = {"l_arm_elx": 5.0, "r_arm_wrx": -3.0}
    with pytest.raises(ProtocolError, match=r"position.l_arm_elx must be in 0..2.35, not 5"):
        check_command({"op": "joints", "position": wanted})
    elbow = c.slot["l_arm_elx"]
    at_limit = {"l_arm_elx": float(c.upper[elbow])}
    assert sim.apply_command(check_command({"op": "joints", "position": at_limit}))["ok"]
    sim.step(1500)
    assert c.position[elbow] > c.upper[elbow] - 0.1  # it went as far as allowed


def test_torques_are_clamped_to_effort_and_speed_limits(make_sim) -> None:
    sim = make_sim("vrc_task_2")
    c = sim.controller
    torques = {"l_arm_wrx": 1e6, "r_gripper": -1e6, "r_arm_ely": 1e4}
    assert sim.apply_command(check_command({"op": "joints", "torque": torques}))["ok"]
    driven = [c.slot[name] for name in torques]
    fastest = np.zeros(len(c.names))
    steps_over = np.zeros(len(driven), dtype=int)  # consecutive steps past the speed limit
    for _ in range(300):
        sim.step(1)
        speed = np.abs(c.velocity)
        fastest = np.maximum(fastest, speed)
        steps_over = np.where(speed[driven] > c.max_velocity[driven], steps_over + 1, 0)
        # Past its limit a driven joint brakes at full effort: under it again the next step.
        assert np.all(steps_over <= 1), dict(zip(torques, steps_over, strict=True))
        assert np.all(np.abs(c.applied) <= c.max_effort + 1e-9)
    # The torques did act: the wrist and the elbow reached their limits.
    assert fastest[c.slot["l_arm_wrx"]] > c.max_velocity[c.slot["l_arm_wrx"]]
    assert fastest[c.slot["r_arm_ely"]] > c.max_velocity[c.slot["r_arm_ely"]]


def test_a_closed_physics_client_cannot_reach_the_next_ones_world() -> None:
    closed = new_client()
    closed.getNumBodies()  # bound to its client id and kept
    closed.disconnect()
    other = new_client()  # pybullet gives it the id just freed
    try:
        other.createMultiBody(baseMass=1.0)
        with pytest.raises(pybullet.error):
            closed.getNumBodies()
    finally:
        other.disconnect()


def test_the_gait_ranges_are_the_same_on_the_wire_and_in_the_walker() -> None:
    from drcsim.gait import _GAIT_RANGES
    from drcsim.protocol import RANGES

    for name, low, high in _GAIT_RANGES:
        if name != "pelvis_height":  # the walker's own, not a team's parameter
            assert RANGES[f"walk.{name}"][:2] == (low, high)
