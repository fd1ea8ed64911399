"""Logs and replay: re-simulating from t=0 with the seed and command log matches."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from drcsim.errors import ReplayMismatch
from drcsim.protocol import check_command
from drcsim.replay import replay


def _record(make_sim, log_dir) -> dict:
    sim = make_sim("vrc_task_1", "2", log_dir=log_dir)
    commands = [
        (0, {"op": "behaviour", "name": "walk", "pose": [1.0, -0.5, 0.0]}),
        (
            333,
            {"op": "joints", "position": {"r_arm_shz": 0.4}, "gains": {"r_arm_shz": [500, 5, 20]}},
        ),
        (777, {"op": "behaviour", "name": "enter_vehicle"}),  # refused: too far, still logged
        (1205, {"op": "behaviour", "name": "stand"}),
        (1500, {"op": "stop"}),
    ]
    for step, command in commands:
        sim.step(step - sim.step_count)
        sim.apply_command(check_command(command))
    return json.loads((log_dir / "final.json").read_text())


def test_replay_reproduces_the_recorded_run(make_sim, tmp_path) -> None:
    final = _record(make_sim, tmp_path / "run")
    assert final["step"] == 1500 and final["end_reason"] == "stopped"
    result = replay(tmp_path / "run")
    assert result.final_digest == final["state_sha256"] and result.states_checked == 150
    done = subprocess.run(
        [sys.executable, "-m", "drcsim.cli", "replay", str(tmp_path / "run"), "--json"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    assert json.loads(done.stdout)["ok"] is True


def test_replay_detects_a_tampered_command_log(make_sim, tmp_path) -> None:
    _record(make_sim, tmp_path / "run")
    commands = tmp_path / "run" / "commands.jsonl"
    commands.write_text(commands.read_text().replace('"r_arm_shz": 0.4', '"r_arm_shz": 0.41'))
    with pytest.raises(ReplayMismatch, match="state differs"):
        replay(tmp_path / "run")
