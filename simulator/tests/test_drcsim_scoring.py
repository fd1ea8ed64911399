"""Scoring rules as data: ordered checkpoints, falls, end of run."""

from __future__ import annotations

from drcsim.models import humanoid
from drcsim.protocol import check_command
from drcsim.scene import yaw_quaternion
from drcsim.scoring import STEADY_S, GateFrame, Memory, Observation, Scorer, evaluate

GATES = {"g1": GateFrame(5.0, 0.0, 0.0, 2.0), "g2": GateFrame(10.0, 0.0, 0.0, 2.0)}
RULES = [
    {"name": "first", "when": {"through_gate": {"body": "robot", "gate": "g1"}}},
    {
        "name": "second",
        "when": {"all": [{"flag": "ready"}, {"at_least": {"quantity": "q", "value": 2.0}}]},
    },
]


def _obs(x: float, ready: bool = False, q: float = 0.0) -> Observation:
    return Observation({"robot": (x, 0.0, 0.9)}, {"ready": ready}, {"q": q})


def test_conditions_evaluate_from_data() -> None:
    crossed = Memory(crossed={("robot", "g1")})
    assert evaluate(RULES[0]["when"], _obs(5.5), GATES, crossed)
    assert not evaluate(RULES[0]["when"], _obs(5.5), GATES)  # never crossed the line
    assert evaluate({"not_flag": "ready"}, _obs(0.0), GATES)
    assert evaluate({"at_most": {"quantity": "q", "value": 1.0}}, _obs(0.0, q=0.5), GATES)


def test_checkpoints_are_awarded_only_in_order() -> None:
    scorer = Scorer(RULES, GATES, time_limit_s=100.0)
    assert scorer.update(4.0, _obs(0.0, ready=True, q=3.0), 0.9, 0.0) == []
    assert scorer.update(5.0, _obs(5.5, ready=True, q=3.0), 0.9, 0.0) == []
    events = scorer.update(5.0 + STEADY_S, _obs(5.6, ready=True, q=3.0), 0.9, 0.0)
    assert [e["checkpoint"] for e in events if e["event"] == "checkpoint"] == [1, 2]
    assert scorer.ended and scorer.end_reason == "complete"


def test_run_ends_at_the_time_limit() -> None:
    scorer = Scorer(RULES, GATES, time_limit_s=3.0)
    scorer.update(2.99, _obs(0.0), 0.9, 0.0)
    assert not scorer.ended
    events = scorer.update(3.0, _obs(0.0), 0.9, 0.0)
    assert events[-1]["event"] == "run_end" and events[-1]["reason"] == "time_limit"


def _collapse(sim) -> dict:
    """Take the legs from the walker and make every joint limp until the robot is down."""
    names = sim.controller.names
    sim.apply_command(check_command({"op": "behaviour", "name": "none"}))
    sim.apply_command(check_command({"op": "joints", "torque": dict.fromkeys(names, 0.0)}))
    for _ in range(40):
        sim.step(100)
        if sim.scorer.down or sim.ended:
            break
    return sim.snapshot()["score"]


def _stood_up(sim) -> None:
    """Put the fallen robot upright where it lies (as a team's own get-up would end)."""
    client, robot = sim.client, sim.scene.robot
    (x, y, _), orn = client.getBasePositionAndOrientation(robot)
    z = humanoid.STAND_PELVIS_HEIGHT + sim.scene.ground_height(x, y)
    yaw = client.getEulerFromQuaternion(orn)[2]
    client.resetBasePositionAndOrientation(robot, [x, y, z], yaw_quaternion(yaw))
    client.resetBaseVelocity(robot, [0, 0, 0], [0, 0, 0])
    sim.controller.reset_to(humanoid.STAND_POSTURE)
    sim.step(10)


def test_falls_are_counted_and_the_third_ends_the_run(make_sim, tmp_path) -> None:
    sim = make_sim("vrc_task_2", "1", log_dir=tmp_path / "run")
    for expected in (1, 2):
        score = _collapse(sim)
        assert score["falls"] == expected and not score["ended"]
        stand = check_command({"op": "behaviour", "name": "stand"})
        assert "the robot is down" in sim.apply_command(stand)["error"]  # no get-up assist
        _stood_up(sim)
        assert sim.apply_command(stand)["ok"]
        sim.step(200)
        assert not sim.scorer.down
    score = _collapse(sim)
    assert score == {"checkpoints": 0, "falls": 3, "ended": True, "reason": "falls"}
    assert sim.step(100) == 0  # nothing runs after the end
    events = (tmp_path / "run" / "score.jsonl").read_text().splitlines()
    assert '"reason": "falls"' in events[-1] and len(events) == 5


def test_simulation_ends_at_its_time_limit(make_sim) -> None:
    sim = make_sim("vrc_task_3", "4", time_limit_s=0.5)
    assert sim.step(2000) == 500
    assert sim.ended and sim.scorer.end_reason == "time_limit"
