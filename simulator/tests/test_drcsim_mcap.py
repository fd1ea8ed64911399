"""run.mcap read back as a stranger would: with the `mcap` reader and each schema in the file."""

from __future__ import annotations

import base64
import json
import signal
from collections import Counter
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from drcsim.client import SimClient
from drcsim.mcaplog import TOPICS, read_messages
from drcsim.rundir import COMMANDS, FINAL, MCAP, SCORE
from mcap.exceptions import McapError
from mcap.reader import make_reader

# Foxglove's well-known schemas as Foxglove and Lichtblick read them: names and top fields.
FOXGLOVE_FIELDS = {
    "foxglove.SceneUpdate": {"deletions", "entities"},
    "foxglove.FrameTransforms": {"transforms"},
    "foxglove.PoseInFrame": {"timestamp", "frame_id", "pose"},
    "foxglove.LaserScan": {
        "timestamp",
        "frame_id",
        "pose",
        "start_angle",
        "end_angle",
        "ranges",
        "intensities",
    },
    "foxglove.CompressedImage": {"timestamp", "frame_id", "data", "format"},
    "foxglove.Log": {"timestamp", "level", "message", "name", "file", "line"},
}
TEAM_TOPICS = ("joint_states", "imu", "lidar", "camera", "contact")


def strict(schema: Any) -> Any:
    """Return a schema that also requires every field it names and no other (Foxglove's own
    leave both open, so a misspelt field would pass them)."""
    if isinstance(schema, dict):
        copy = {key: strict(value) for key, value in schema.items()}
        properties = copy.get("properties")
        if isinstance(properties, dict) and copy.get("type") == "object":
            copy.setdefault("required", sorted(properties))
            copy.setdefault("additionalProperties", False)
        return copy
    if isinstance(schema, list):
        return [strict(item) for item in schema]
    return schema


def validate_file(path: Path) -> tuple[Counter[str], list[int], dict[str, list[Any]]]:
    """Validate every message against the schema stored with it; return the count per topic,
    the log times and the decoded messages per topic."""
    counts: Counter[str] = Counter()
    times: list[int] = []
    decoded: dict[str, list[Any]] = {}
    validators: dict[int, jsonschema.Draft202012Validator] = {}
    with path.open("rb") as handle:
        for schema, channel, message in make_reader(handle).iter_messages(log_time_order=False):
            assert schema is not None and schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            assert TOPICS[channel.topic] == schema.name
            if schema.id not in validators:
                document = json.loads(schema.data)
                assert document["title"] == schema.name
                if schema.name.startswith("foxglove."):  # ours say what they require
                    document = strict(document)
                validators[schema.id] = jsonschema.Draft202012Validator(document)
            data = json.loads(message.data)
            validators[schema.id].validate(data)
            counts[channel.topic] += 1
            times.append(message.log_time)
            decoded.setdefault(channel.topic, []).append(data)
    return counts, times, decoded


def test_a_served_run_reads_back_message_by_message(server: Any, tmp_path: Path) -> None:
    process, port = server("vrc_task_2", "1", logs=True)
    received: Counter[str] = Counter()
    replies = 0
    with SimClient("127.0.0.1", port) as client:
        client.subscribe(*TEAM_TOPICS)
        while not received:  # until the server has our subscriptions
            client.step(10)
            replies += 1
            while (got := client.receive(0.05)) is not None:
                received[got[0]] += 1
        # refused (the stand behaviour owns the joint) and still recorded, as in commands.jsonl
        assert not client.request({"op": "joints", "position": {"l_leg_kny": 0.2}})["ok"]
        assert client.behaviour("walk", pose=[1.0, 0.0, 0.0])["ok"]
        for _ in range(30):  # past 1 s: a key frame of /tf
            client.step(40)
            replies += 1
            while (got := client.receive(0.05)) is not None:
                received[got[0]] += 1
        while (got := client.receive(0.5)) is not None:
            received[got[0]] += 1
        assert client.request({"op": "stop"})["ok"]
    assert process.wait(timeout=60) == 0
    folder = tmp_path / "run-0"
    final = json.loads((folder / FINAL).read_text())

    counts, times, decoded = validate_file(folder / MCAP)

    with (folder / MCAP).open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None and summary.statistics is not None
    by_topic = {
        summary.channels[channel].topic: count
        for channel, count in summary.statistics.channel_message_counts.items()
    }
    assert by_topic == dict(counts)
    assert summary.statistics.message_count == sum(counts.values())
    assert summary.statistics.message_start_time == min(times) == 0
    end = round(final["sim_time"] * 1e9)
    assert summary.statistics.message_end_time == max(times) == end
    assert summary.chunk_indexes and all(i.compression == "zstd" for i in summary.chunk_indexes)
    # every schema a channel uses is stored, once
    assert sorted(s.name for s in summary.schemas.values()) == sorted({TOPICS[t] for t in counts})

    # the world once; every moving link's pose at 100 Hz; the estimate with it
    assert counts["/world/scene"] == 1
    assert counts["/tf"] == counts["/robot/estimate"] == final["step"] // 10
    # a key frame each second holds every frame; between them, the frames that moved
    key_frames = [
        m
        for m in decoded["/tf"]
        if m["transforms"][:1] and m["transforms"][0]["timestamp"]["nsec"] == 0
    ]
    frames = {t["child_frame_id"] for t in decoded["/tf"][0]["transforms"]}
    assert {"robot/pelvis", "robot/head", "robot/l_foot"} <= frames
    assert len(key_frames) == final["step"] // 1000  # at 1 s, 2 s, ...
    assert all({t["child_frame_id"] for t in m["transforms"]} == frames for m in key_frames)
    entities = decoded["/world/scene"][0]["entities"]
    hung = {e["frame_id"] for e in entities if e["frame_locked"]}
    assert "robot/pelvis" in hung and hung <= frames  # every moving shape follows a frame
    # what the team received, as it received it
    for topic in ("lidar", "camera"):
        assert received[topic] > 0
    assert counts["/team/lidar"] == received["lidar"]
    assert counts["/team/camera/left"] == counts["/team/camera/right"] == received["camera"]
    assert counts["/team/joint_states"] == received["joint_states"]
    assert counts["/team/robot_state"] == replies  # every lock-step reply
    image = base64.b64decode(decoded["/team/camera/left"][0]["data"])
    assert image.startswith(b"\x89PNG\r\n\x1a\n")
    assert len(decoded["/team/lidar"][0]["ranges"]) == 1081
    # every command with its sender; every score log line, at its simulated time
    commands = (folder / COMMANDS).read_text().splitlines()
    assert counts["/commands"] == len(commands) == 3
    assert {c["source"] for c in decoded["/commands"]} == {"127.0.0.1"}
    assert [c["command"]["op"] for c in decoded["/commands"]] == ["joints", "behaviour", "stop"]
    score_lines = [json.loads(line) for line in (folder / SCORE).read_text().splitlines()]
    assert [e["event"] for e in decoded["/score/events"]] == score_lines
    assert decoded["/score"][-1]["message"].startswith("run ended: stopped")


def test_the_foxglove_schemas_are_pinned(server: Any, tmp_path: Path) -> None:
    process, port = server("vrc_task_2", "1", logs=True)
    with SimClient("127.0.0.1", port) as client:
        client.step(20)
        assert client.request({"op": "stop"})["ok"]
    assert process.wait(timeout=60) == 0
    with (tmp_path / "run-0" / MCAP).open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None
    stored = {s.name: json.loads(s.data) for s in summary.schemas.values()}
    for name, document in stored.items():
        if name.startswith("foxglove."):
            assert set(document["properties"]) == FOXGLOVE_FIELDS[name]
    transform = stored["foxglove.FrameTransforms"]["properties"]["transforms"]["items"]
    assert set(transform["properties"]) == {
        "timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation",
    }  # fmt: skip


def test_a_killed_simulator_leaves_a_file_readable_to_its_last_chunk(
    server: Any, tmp_path: Path
) -> None:
    process, port = server("vrc_task_2", "1", logs=True)
    with SimClient("127.0.0.1", port) as client:
        for _ in range(10):  # a few chunks
            assert client.request({"op": "step", "steps": 500}, timeout_s=120)["ok"]
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    path = tmp_path / "run-0" / MCAP
    with path.open("rb") as handle:
        with pytest.raises(McapError):  # no footer: no summary to seek with
            make_reader(handle).get_summary()
    times = [message.log_time for _, channel, message in read_messages(path)]
    assert len(times) > 100 and max(times) >= 1_000_000_000  # whole chunks survived
    assert times == sorted(times)
