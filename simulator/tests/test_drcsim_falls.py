"""A fall ends what the robot was doing, and a fallen robot earns nothing (issue 32, item 2)."""

from __future__ import annotations

import math

from drcsim.local import LocalClient
from drcsim.models import humanoid
from drcsim.scene import yaw_quaternion
from drcsim.scoring import STEADY_S, GateFrame, Observation, Scorer

GATES = {"g1": GateFrame(5.0, 0.0, 0.0, 2.0)}
RULES = [{"name": "first", "when": {"through_gate": {"body": "robot", "gate": "g1"}}}]
UP, DOWN = (0.9, 0.0), (0.3, 1.4)  # pelvis height and tilt


def _at(x: float) -> Observation:
    return Observation({"robot": (x, 0.0, 0.9)}, {}, {})


def _run(scorer: Scorer, samples: list[tuple[float, float, tuple[float, float]]]) -> int:
    for t, x, (height, tilt) in samples:
        scorer.update(t, _at(x), height, tilt)
    return scorer.reached


def test_a_crossing_counts_once_the_robot_has_stayed_up_after_it() -> None:
    scorer = Scorer(RULES, GATES, time_limit_s=100.0)
    assert _run(scorer, [(4.0, 4.9, UP), (4.01, 5.1, UP)]) == 0  # not yet: it may be a dive
    assert _run(scorer, [(4.01 + STEADY_S, 5.2, UP)]) == 1


def test_a_dive_through_the_line_earns_nothing_even_if_the_robot_stands_up_beyond_it() -> None:
    scorer = Scorer(RULES, GATES, time_limit_s=100.0)
    dive = [(4.0, 4.9, UP), (4.01, 5.1, UP), (4.5, 5.6, DOWN), (9.0, 5.8, DOWN)]
    up_again = [(10.0 + 0.5 * i, 6.1, UP) for i in range(20)]  # up beyond the line for 10 s
    assert _run(scorer, dive + up_again) == 0 and scorer.falls == 1


def test_nothing_is_credited_while_down_or_getting_up() -> None:
    rules = [{"name": "flag", "when": {"flag": "ready"}}]
    scorer = Scorer(rules, GATES, time_limit_s=100.0)
    ready = Observation({"robot": (0.0, 0.0, 0.9)}, {"ready": True}, {})
    scorer.update(1.0, ready, *DOWN)
    scorer.update(20.0, ready, *DOWN)
    scorer.update(20.5, ready, *UP)
    assert scorer.reached == 0  # down, then only just up
    scorer.update(20.5 + STEADY_S, ready, *UP)
    assert scorer.reached == 1
    # And a line crossed in the seconds of getting up is no crossing, even much later.
    scorer = Scorer(RULES, GATES, time_limit_s=100.0)
    assert _run(scorer, [(1.0, 4.5, DOWN), (2.0, 4.9, UP), (2.5, 5.3, UP), (20.0, 5.5, UP)]) == 0


def _stand_at(sim, x: float, y: float, yaw: float) -> None:
    """Put the robot upright at a pose (what a get-up of the team's own would end in)."""
    client, robot = sim.client, sim.scene.robot
    z = humanoid.STAND_PELVIS_HEIGHT + sim.scene.ground_height(x, y)
    client.resetBasePositionAndOrientation(robot, [x, y, z], yaw_quaternion(yaw))
    client.resetBaseVelocity(robot, [0, 0, 0], [0, 0, 0])
    sim.controller.reset_to(humanoid.STAND_POSTURE)


def _pelvis(sim) -> tuple[float, float, float]:
    return tuple(sim.client.getBasePositionAndOrientation(sim.scene.robot)[0])


def test_the_dive_earns_nothing(make_sim, place) -> None:
    sim = make_sim("vrc_task_2", "1")
    place(sim, 3.55, 0.0, 0.0)  # 0.45 m before gate_1's line (x = 4)
    client = LocalClient(sim)
    assert client.behaviour("none")["ok"]
    lean = {"l_leg_aky": -0.6, "r_leg_aky": -0.6}  # the stand has -0.3: toes down
    assert client.request({"op": "joints", "position": lean})["ok"]
    state = client.step(3000)
    assert state["score"]["falls"] == 1 and _pelvis(sim)[0] > 4.0  # it lies beyond the line
    refused = client.request({"op": "behaviour", "name": "stand"})
    assert refused["ok"] is False and "down" in refused["error"]  # no get-up assist
    state = client.step(5000)
    assert state["score"]["checkpoints"] == 0
    # Even stood up beyond the line (as the old recovery did, 1.1 m on), the gate is not earned.
    _stand_at(sim, 5.1, 0.0, 0.0)
    client.step(10)
    assert client.behaviour("stand")["ok"]
    state = client.step(int(2 * STEADY_S * 1000))
    assert state["score"] == {"checkpoints": 0, "falls": 1, "ended": False, "reason": None}


def test_the_crawl_earns_nothing(make_sim, place) -> None:
    sim = make_sim("vrc_task_2", "1")
    place(sim, 2.2, 0.0, 0.0)
    client = LocalClient(sim)
    assert client.behaviour("walk", pose=[7.0, 0.0, 0.0])["ok"]
    while _pelvis(sim)[0] < 2.8:
        state = client.step(100)
        assert state["score"]["falls"] == 0
    # Knocked over sideways mid-walk (a push on the pelvis until it is down).
    while not sim.scorer.down:
        sim.client.applyExternalForce(sim.scene.robot, -1, [0, 900, 0], [0, 0, 0], 2)
        sim.step(1)
    lying = _pelvis(sim)
    state = client.step(100)
    assert state["behaviour"]["mode"] == "none" and state["behaviour"]["walk"].startswith("fell")
    refused = client.request({"op": "behaviour", "name": "walk", "pose": [7.0, 0.0, 0.0]})
    assert refused["ok"] is False and "down" in refused["error"]
    for _ in range(3):
        state = client.step(5000)
    now = _pelvis(sim)
    assert math.hypot(now[0] - lying[0], now[1] - lying[1]) < 0.5  # it went nowhere
    assert now[0] < 4.0 and state["score"]["checkpoints"] == 0
