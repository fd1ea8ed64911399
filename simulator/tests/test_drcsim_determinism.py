"""Same world, configuration and commands: bitwise-identical state, with or without sensors."""

from __future__ import annotations

from typing import Any

from drcsim.protocol import check_command
from drcsim.sensors import SensorSettings

SCRIPT: list[tuple[int, dict[str, Any]]] = [
    (0, {"op": "behaviour", "name": "walk", "pose": [1.5, 0.5, 0.3]}),
    (400, {"op": "joints", "position": {"l_arm_shx": -0.5, "r_arm_elx": -1.0}}),
    (
        900,
        {
            "op": "behaviour",
            "name": "reach",
            "hand": "left",
            "target": [0.4, 0.3, 0.2],
            "frame": "pelvis",
        },
    ),
]
STEPS = 1500


def _run(sim: Any) -> list[float]:
    for step, command in SCRIPT:
        sim.step(step - sim.step_count)
        assert sim.apply_command(check_command(command))["ok"]
    sim.step(STEPS - sim.step_count)
    return list(sim.state_vector())


def test_two_runs_reach_identical_state(make_sim) -> None:
    first = _run(make_sim("vrc_task_2", "3"))
    second = _run(make_sim("vrc_task_2", "3"))
    assert first == second


def test_subscribed_sensors_do_not_change_the_physics(make_sim) -> None:
    quiet = _run(make_sim("vrc_task_3", "2"))
    received: list[str] = []
    settings = SensorSettings(camera_width=80, camera_height=60, camera_hz=50.0, lidar_beams=181)
    sim = make_sim(
        "vrc_task_3", "2", sensors=settings, publish=lambda topic, _: received.append(topic)
    )
    sim.active_topics = {"camera", "lidar", "imu", "joint_states", "contact", "robot_state"}
    assert _run(sim) == quiet
    assert {"camera", "lidar", "imu", "joint_states", "contact"} <= set(received)


def test_different_configurations_differ(make_sim) -> None:
    assert _run(make_sim("vrc_task_2", "1")) != _run(make_sim("vrc_task_2", "5"))
