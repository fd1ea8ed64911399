"""World documents: the schema check, digests, and a handed-over document building the run."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import pytest
from drcsim.client import SimClient
from drcsim.errors import WorldError
from drcsim.replay import replay
from drcsim.worlds import (
    WORLD_NAMES,
    check_document,
    document_digest,
    load_world,
    shipped_document,
)


@pytest.mark.parametrize("name", WORLD_NAMES)
def test_every_shipped_world_passes_the_check(name: str) -> None:
    document = shipped_document(name)
    assert check_document(document) is document
    reordered = json.loads(json.dumps(document, sort_keys=True, indent=4))
    assert document_digest(reordered) == document_digest(document)


def _broken(change: str) -> dict:
    doc = copy.deepcopy(shipped_document("vrc_task_1"))
    if change == "missing":
        del doc["checkpoints"]
    elif change == "model":
        doc["objects"][0]["model"] = "tank"
    elif change == "gate":
        doc["checkpoints"][1]["when"]["through_gate"]["gate"] = "gate_9"
    elif change == "override":
        doc["configs"]["2"]["objects"]["gate_9"] = {"pose": [1, 2, 3]}
    elif change == "pose":
        doc["configs"]["4"]["objects"]["gate_1"]["pose"] = [20.0, "left"]
    elif change == "typo":
        doc["configs"]["3"]["grund"] = {"friction": 0.5}
    elif change == "terrain":  # a field the terrain no longer has (the harness's walk speed)
        doc = copy.deepcopy(shipped_document("vrc_task_2"))
        doc["configs"]["3"]["terrain"]["rubble"]["walk_speed"] = 0.55
    return doc


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ("missing", "missing field(s) checkpoints"),
        ("model", "vrc_task_1.objects[0].model: must be one of gate"),
        ("gate", "'gate_9' is not a gate of this world"),
        ("override", "configuration overrides unknown object 'gate_9'"),
        ("pose", "vrc_task_1.configs.4.objects.gate_1.pose: must be a list of 3 numbers"),
        ("typo", "vrc_task_1.configs.3: unknown field(s) grund"),
        ("terrain", "vrc_task_2.configs.3.terrain.rubble: unknown field(s) walk_speed"),
    ],
)
def test_a_broken_document_is_refused_saying_where(change: str, says: str) -> None:
    with pytest.raises(WorldError) as caught:
        check_document(_broken(change))
    assert says in str(caught.value)


def test_a_handed_over_document_changes_the_built_scene(make_sim) -> None:
    doc = shipped_document("vrc_task_1")
    doc["configs"]["2"]["objects"]["gate_1"]["pose"] = [22.5, 3.0, 0.0]
    doc["configs"]["2"]["ground"] = {"friction": 0.6}
    sim = make_sim("vrc_task_1", "2", world_document=doc)
    gate = sim.scene.gates["gate_1"]
    assert (gate.x, gate.y) == (22.5, 3.0) and sim.spec.ground_friction == 0.6
    assert sim.meta()["world_digest"] == document_digest(doc)
    assert load_world("vrc_task_1", "2").objects["gate_1"]["pose"] == [20.0, 3.4, 0.15]


def test_serve_loads_the_world_file_and_scores_by_its_rules(server, tmp_path: Path) -> None:
    doc = shipped_document("vrc_task_2")
    # a first checkpoint that holds at once: the run scores by the handed-over rules
    doc["checkpoints"][0] = {"name": "standing at the start", "when": {"not_flag": "never"}}
    world_file = tmp_path / "world.json"
    world_file.write_text(json.dumps(doc))
    process, port = server("vrc_task_2", "1", "--world-file", str(world_file), logs=True)
    with SimClient("127.0.0.1", port) as client:
        # credited once the robot has stood STEADY_S (3 s) after it holds: 3.1 s of steps
        for _ in range(31):
            state = client.step(100)
        assert state["score"]["checkpoints"] == 1
    process.terminate()
    assert process.wait(timeout=30) == 0
    run = tmp_path / "run-0"
    assert '"name": "standing at the start"' in (run / "score.jsonl").read_text()
    assert json.loads((run / "meta.json").read_text())["world_digest"] == document_digest(doc)
    assert json.loads((run / "world.json").read_text()) == doc
    assert replay(run).score == 1


def test_serve_refuses_a_broken_world_file_in_one_line(tmp_path: Path) -> None:
    world_file = tmp_path / "world.json"
    world_file.write_text(json.dumps(_broken("gate")))
    argv = ["serve", "--world", "vrc_task_1", "--world-file", str(world_file), "--port", "0"]
    result = subprocess.run(
        [sys.executable, "-m", "drcsim.cli", *argv], capture_output=True, text=True, timeout=60
    )
    assert result.returncode != 0
    assert "'gate_9' is not a gate of this world" in result.stderr.strip().splitlines()[-1]
