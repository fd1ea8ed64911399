"""The valve and the vehicle's controls move only when the robot's own limbs move them."""

from __future__ import annotations

import math

from drcsim.handles import set_friction
from drcsim.protocol import check_command
from drcsim.reach import ARM_JOINTS


def _command(sim, **message) -> dict:
    return sim.apply_command(check_command(message))


def _until(sim, done, limit_steps: int) -> None:
    for _ in range(limit_steps // 100):
        sim.step(100)
        if done():
            return


def test_the_valve_turns_only_with_a_hand_holding_its_rim(make_sim, place) -> None:
    sim = make_sim("vrc_task_3", "1")
    valve = sim.behaviours.valve
    x, y, z = valve.centre()
    # Refused (the hand is far from the valve): nothing changes, the arm's reach goes on.
    assert _command(sim, op="behaviour", name="reach", hand="left", target=[0.3, 0.3, 1.0])["ok"]
    refused = _command(sim, op="behaviour", name="turn_valve", hand="left")
    assert refused["ok"] is False and "not at the valve" in refused["error"]
    assert "left" in sim.behaviours.reaches and valve.status_word == "idle"
    assert _command(sim, op="behaviour", name="arm_rest", hand="left")["ok"]
    place(sim, x - 0.5, y - 0.3, 0.0)
    # A hand closed in front of the wheel's centre holds nothing: only the rim can be held.
    assert _command(sim, op="behaviour", name="reach", hand="left", target=[x - 0.12, y, z])["ok"]
    sim.step(1500)
    assert _command(sim, op="behaviour", name="grasp", hand="left")["grasped"] is None
    assert _command(sim, op="behaviour", name="release", hand="left")["ok"]
    rim = [x, y + 0.12 * math.cos(0.1), z + 0.12 * math.sin(0.1)]  # the standpipe faces -x
    assert _command(sim, op="behaviour", name="reach", hand="left", target=rim)["ok"]
    sim.step(1500)
    assert _command(sim, op="behaviour", name="grasp", hand="left")["grasped"] == "valve"
    # Free of the reach, the arm is the team's: its own joint commands turn the valve (a
    # small move: swung to the rest posture, the arm held on the rim would pull the robot over).
    assert _command(sim, op="behaviour", name="arm_rest", hand="left")["ok"]
    arm = {n: float(sim.controller.position[sim.controller.slot[n]]) for n in ARM_JOINTS["left"]}
    assert _command(sim, op="joints", position={**arm, "l_arm_shx": arm["l_arm_shx"] + 0.25})["ok"]
    before = valve.angle()
    sim.step(1000)
    assert abs(valve.angle() - before) > 0.1
    assert _command(sim, op="behaviour", name="release", hand="left")["ok"]
    sim.step(200)
    let_go = valve.angle()
    sim.step(500)
    assert abs(valve.angle() - let_go) < 0.01  # friction holds a valve nobody turns
    # turn_valve takes the rim and strokes it round; against a seized stem it says so.
    assert _command(sim, op="behaviour", name="reach", hand="left", target=[x - 0.1, y, z])["ok"]
    sim.step(1500)
    assert _command(sim, op="behaviour", name="turn_valve", hand="left", angle=1.0)["ok"]
    refused = _command(sim, op="joints", position={"l_arm_elx": 0.5})
    assert refused["ok"] is False and "turn_valve (left hand)" in refused["error"]
    _until(sim, lambda: valve.status_word != "turning", 6000)
    assert valve.status_word == "idle" and valve.angle() >= let_go + 0.95
    assert valve.handle is not None
    set_friction(sim.scene, valve.handle, 500.0)
    seized = valve.angle()
    assert _command(sim, op="behaviour", name="turn_valve", hand="left", angle=1.0)["ok"]
    _until(sim, lambda: valve.status_word != "turning", 8000)
    assert valve.status_word.startswith("stalled: the arm cannot follow the rim")
    assert abs(valve.angle() - seized) < 0.05 and sim.behaviours.grasps.held == {}
