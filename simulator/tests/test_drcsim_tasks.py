"""Every checkpoint of every task is reachable by scripted inputs (the example controller)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from drcsim.example_controller import ExampleController
from drcsim.local import LocalClient


@pytest.mark.parametrize("world", ["vrc_task_1", "vrc_task_3"])
def test_all_four_checkpoints_in_order_in_configuration_1(make_sim, tmp_path, world) -> None:
    sim = make_sim(world, "1", log_dir=tmp_path / "run")
    score = ExampleController(LocalClient(sim)).run()
    assert score == {"checkpoints": 4, "falls": 0, "ended": True, "reason": "complete"}
    lines = (tmp_path / "run" / "score.jsonl").read_text().splitlines()
    events = [json.loads(line) for line in lines]
    checkpoints = [e for e in events if e["event"] == "checkpoint"]
    assert [e["checkpoint"] for e in checkpoints] == [1, 2, 3, 4]
    times = [e["sim_time"] for e in checkpoints]
    assert times == sorted(times) and all("wall_time" in e for e in events)


def test_example_controller_over_the_network(server) -> None:
    _, port = server("vrc_task_2", "1")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "drcsim.cli",
            "example-controller",
            "--server",
            "127.0.0.1",
            "--port",
            str(port),
            "--world",
            "vrc_task_2",
            "--timeout",
            "120",
        ],
        capture_output=True,
        text=True,
        timeout=180,
        check=True,
    )
    score = json.loads(done.stdout.strip().splitlines()[-1])
    assert score["checkpoints"] == 4 and score["reason"] == "complete"
