"""Scoring that cannot be gamed: one test per hole a team could use."""

from __future__ import annotations

import math

from drcsim.protocol import check_command
from drcsim.scoring import STEADY_S, GateFrame, Observation, Scorer
from drcsim.worlds import load_world

GATE = {"g": GateFrame(5.0, 0.0, 0.0, 2.0)}
THROUGH = [{"name": "through", "when": {"through_gate": {"body": "robot", "gate": "g"}}}]


def _at(x: float, y: float, **quantities: float) -> Observation:
    return Observation({"robot": (x, y, 0.9)}, {}, quantities)


def _path(scorer: Scorer, points: list[tuple[float, float]]) -> int:
    """Walk `points` 10 ms apart (the robot long up), then stand at the last one."""
    for tick, (x, y) in enumerate(points):
        scorer.update(STEADY_S + tick * 0.01, _at(x, y), 0.9, 0.0)
    scorer.update(2 * STEADY_S + len(points) * 0.01, _at(*points[-1]), 0.9, 0.0)
    return scorer.reached


def test_a_gate_counts_only_when_crossed_between_its_posts_in_its_direction() -> None:
    # Stepping into the zone past the gate line from the side earns nothing.
    assert (
        _path(Scorer(THROUGH, GATE, 100.0), [(5.5, 3.0), (5.5, 2.0), (5.5, 0.5), (5.5, 0.0)]) == 0
    )
    # Crossing the line outside the posts, or backwards, earns nothing.
    assert _path(Scorer(THROUGH, GATE, 100.0), [(4.5, 1.5), (5.5, 1.5), (5.5, 0.0)]) == 0
    assert _path(Scorer(THROUGH, GATE, 100.0), [(6.0, 0.0), (4.5, 0.0)]) == 0
    # Through the opening from the front: the checkpoint.
    assert _path(Scorer(THROUGH, GATE, 100.0), [(3.0, 0.5), (4.96, 0.5), (5.02, 0.5)]) == 1


def test_crossing_back_undoes_a_gate_not_yet_awarded() -> None:
    rules = [{"name": "ready", "when": {"flag": "ready"}}, *THROUGH]
    scorer = Scorer(rules, GATE, 100.0)
    for tick, x in enumerate((4.9, 5.1, 4.9)):
        scorer.update(STEADY_S + tick * 0.01, _at(x, 0.0), 0.9, 0.0)
    ready = Observation({"robot": (4.9, 0.0, 0.9)}, {"ready": True}, {})
    scorer.update(2 * STEADY_S, ready, 0.9, 0.0)
    assert scorer.reached == 1  # the gate was crossed back before its turn came


def test_the_valve_counts_only_once_the_hose_is_connected() -> None:
    spec = load_world("vrc_task_3", 1)
    scorer = Scorer(spec.checkpoints, {}, 100.0)

    def observe(tick: int, connected: bool, valve: float) -> int:
        flags = {"hose_grasped": not connected, "hose_connected": connected}
        quantities = {"hose_lift": 0.2, "hose_inlet_distance": 0.0, "valve_angle": valve}
        scorer.update(STEADY_S + tick * 0.01, Observation({}, flags, quantities), 0.9, 0.0)
        return scorer.reached

    assert observe(0, False, 0.0) == 2  # picked up and aligned
    assert observe(1, False, 4.0) == 2  # the valve turned first: nothing for it
    assert observe(2, True, 4.0) == 3  # connected; the earlier turning does not count
    assert observe(3, True, 6.0) == 3
    assert observe(4, True, 7.2) == 4  # half a turn after the connection


def _command(sim, **message) -> dict:
    return sim.apply_command(check_command(message))


def _yaw(sim) -> float:
    _, orn = sim.client.getBasePositionAndOrientation(sim.scene.robot)
    return float(sim.client.getEulerFromQuaternion(orn)[2])


def test_the_configured_start_yaw_holds(make_sim) -> None:
    sim = make_sim("vrc_task_1", "3")
    assert load_world("vrc_task_1", 3).robot_start[2] == 0.6
    sim.step(1000)
    assert abs(_yaw(sim) - 0.6) < 0.02


def _walk(sim, pose: list[float], limit_steps: int = 30_000) -> str:
    assert _command(sim, op="behaviour", name="walk", pose=pose)["ok"]
    for _ in range(limit_steps // 100):
        sim.step(100)
        if sim.behaviours.walk_status != "walking":
            break
    return str(sim.behaviours.walk_status)


def test_a_walk_is_done_only_when_the_pelvis_is_at_the_goal(make_sim) -> None:
    sim = make_sim("vrc_task_2", "1")
    assert _walk(sim, [1.5, 0.4, 0.5]) == "done"
    pos, _ = sim.client.getBasePositionAndOrientation(sim.scene.robot)
    assert math.hypot(pos[0] - 1.5, pos[1] - 0.4) <= 0.02 and abs(_yaw(sim) - 0.5) <= 0.04


def test_walking_into_the_vehicle_does_not_shove_it(make_sim) -> None:
    sim = make_sim("vrc_task_1", "1")
    car = sim.scene.vehicle
    before = sim.client.getBasePositionAndOrientation(car)[0]
    status = _walk(sim, [2.5, 1.9, 0.0], limit_steps=15_000)
    after = sim.client.getBasePositionAndOrientation(car)[0]
    assert status != "done"  # the walker leans on the car, it does not shove it
    assert math.dist(before[:2], after[:2]) < 0.3  # the harness shoved it 1.87 m


def test_joints_a_behaviour_owns_are_refused_with_the_reason(make_sim) -> None:
    sim = make_sim("vrc_task_2", "1")
    reply = _command(sim, op="joints", position={"l_leg_kny": 1.0, "l_arm_elx": 0.5})
    assert reply["ok"] is False and "l_leg_kny (owned by stand)" in reply["error"]
    slot = sim.controller.slot["l_arm_elx"]
    assert sim.controller.target[slot] != 0.5  # all or nothing: the free arm joint is untouched
    assert _command(
        sim, op="behaviour", name="reach", hand="left", target=[0.4, 0.3, 0.2], frame="pelvis"
    )["ok"]
    reply = _command(sim, op="joints", torque={"l_arm_elx": 1.0})
    assert reply["ok"] is False and "reach" in reply["error"]
    assert _command(sim, op="behaviour", name="none")["ok"]
    assert _command(sim, op="joints", position={"l_leg_kny": 1.0, "l_arm_elx": 0.5})["ok"]


def test_the_valve_turns_only_while_a_hand_is_on_it(make_sim, place) -> None:
    sim = make_sim("vrc_task_3", "1")
    valve = sim.scene.course["standpipe"]["valve"]
    place(sim, valve[0] - 0.5, valve[1] - 0.3, 0.0)
    assert _command(
        sim, op="behaviour", name="reach", hand="left", target=[valve[0] - 0.12, valve[1], valve[2]]
    )["ok"]
    sim.step(3000)
    assert _command(sim, op="behaviour", name="turn_valve", hand="left", angle=6.0)["ok"]
    sim.step(500)
    turned = sim.behaviours.valve.angle()
    assert turned > 0.3
    assert _command(sim, op="behaviour", name="arm_rest", hand="left")["ok"]
    sim.step(1500)
    assert sim.behaviours.status()["valve"] == "hand_off"
    assert sim.behaviours.valve.angle() < turned + 0.5
