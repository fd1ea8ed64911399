"""The viewer's data: the scene description, the `poses` topic, poses rebuilt from the state log."""

from __future__ import annotations

import io
import itertools
import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest
import zmq
from drcsim.cli import main
from drcsim.client import LOCAL_PORT_OFFSET, SimClient
from drcsim.engine import RunOptions, Simulation
from drcsim.errors import ClientError
from drcsim.viewer import StateLogPoses, describe_scene, link_poses
from drcsim.watch import watch

ServerFactory = Callable[..., tuple[Any, int]]


def test_the_scene_holds_every_body_with_its_shapes(make_sim: Callable[..., Simulation]) -> None:
    sim = make_sim("vrc_task_1")
    scene = describe_scene(sim.client)
    by_id = {body["id"]: body for body in scene["bodies"]}
    assert set(by_id) == {sim.client.getBodyUniqueId(i) for i in range(sim.client.getNumBodies())}
    robot = by_id[sim.scene.robot]
    assert robot["moving"] and robot["links"][0] == "pelvis" and len(robot["links"]) == 31
    assert {"l_foot", "r_hand", "head"} <= set(robot["links"])
    kinds = {shape["type"] for shape in robot["shapes"]}
    assert "box" in kinds and all(len(s["rgba"]) == 4 for s in robot["shapes"])
    assert by_id[sim.scene.vehicle]["moving"]  # type: ignore[index]
    gate = by_id[sim.scene.gates["gate_1"].body]
    assert not gate["moving"] and len(gate["poses"]) == 7 * len(gate["links"])
    assert abs(gate["poses"][0] - sim.scene.gates["gate_1"].x) < 1e-6
    ground = by_id[sim.scene.ground]  # no visual shape: drawn from its collision shape
    assert [s["type"] for s in ground["shapes"]] == ["plane"]


def test_poses_rebuilt_from_the_state_log_match_the_simulation(tmp_path: Path) -> None:
    sim = Simulation("vrc_task_2", "1", RunOptions(log_dir=tmp_path / "run"))
    sim.apply_command({"op": "behaviour", "name": "walk", "pose": [3.0, 0.5, 0.0]})
    sim.step(1500)
    live = {body: link_poses(sim.client, body) for body in sim.state_bodies()}
    step = sim.step_count
    sim.close()
    poses = StateLogPoses(tmp_path / "run")
    try:
        assert len(list(poses.frames(every=1))) == 150
        frames = list(poses.frames(every=1, start=1.4))  # from the mark of second 1 on
        assert [f["step"] for f in poses.frames(every=5, start=0.3, stop=0.75)] == [
            300,
            350,
            400,
            450,
            500,
            550,
            600,
            650,
            700,
        ]
    finally:
        poses.close()
    assert frames[0]["t"] == 1.4 and frames[-1]["step"] == step
    for body, expected in live.items():
        got = frames[-1]["poses"][str(body)]
        positions = [i for i in range(len(expected)) if i % 7 < 3]
        assert max(abs(got[i] - expected[i]) for i in positions) < 1e-3  # 1 mm, every link


def test_the_poses_topic_is_computed_only_while_subscribed_on_loopback(
    server: ServerFactory,
) -> None:
    _, port = server("vrc_task_2", "1")
    with SimClient("127.0.0.1", port) as client, _LoopbackTopics(port) as local:
        client.step(100)
        assert all(topic != "poses" for topic, _ in local.drain())
        local.subscribe("poses")
        start = _await_poses(client, local)
        client.step(100)  # 0.1 s: three frames at 30 Hz
        frames = [message for topic, message in local.drain() if topic == "poses"]
        assert [f["step"] for f in frames] == _pose_steps(start, 100)
        robot_poses = next(iter(frames[-1]["poses"].values()))
        assert len(robot_poses) == 7 * 31 and abs(robot_poses[2] - 0.9) < 0.3


def test_a_lan_client_never_gets_ground_truth_even_while_someone_watches(
    server: ServerFactory, tmp_path: Path
) -> None:
    # the server listens on a "LAN" address and allows the whole network; team code
    # connects from another address of it, as a field computer would
    _, port = server(
        "vrc_task_2", "1", "--bind", "127.0.0.2", "--allow", "127.0.0.0/8", host="127.0.0.2"
    )
    with (
        SimClient("127.0.0.2", port, source="127.0.0.3") as team,
        _LoopbackTopics(port) as local,
        zmq.Context() as context,
        context.socket(zmq.SUB) as sniffer,
    ):
        assert "poses" not in team.hello()["topics"]
        with pytest.raises(ClientError, match="poses is ground truth"):
            team.subscribe("poses")
        team.subscribe("clock")
        sniffer.connect(f"tcp://127.0.0.3:0;127.0.0.2:{port + 1}")
        sniffer.setsockopt(zmq.SUBSCRIBE, b"")  # everything the LAN socket sends
        sniffer.setsockopt(zmq.SUBSCRIBE, b"poses")  # and asking by name, past the client
        local.subscribe("poses")
        for _ in range(100):  # until the sniffer's subscriptions have reached the server
            if sniffer.poll(100):
                break
            team.step(10)
        start = _await_poses(team, local)
        team.step(100)
        frames = [m for topic, m in local.drain() if topic == "poses"]
        assert [f["step"] for f in frames] == _pose_steps(start, 100)
        assert team.receive(timeout_s=1.0) is not None  # the LAN socket works...
        seen = set()
        while sniffer.poll(300):
            seen.add(sniffer.recv_multipart()[0])
        assert b"clock" in seen and b"poses" not in seen  # ...but never carries poses
        team.stop()
    log = (tmp_path / "server-0.log").read_text()
    assert "refused a subscription to 'poses' on the LAN" in log


POSE_EVERY = round(1000 / 30)  # physics steps between `poses` frames at the default rate


def _pose_steps(start: int, steps: int) -> list[int]:
    """Return the steps after `start` (for `steps` more) that publish a `poses` frame."""
    return [s for s in range(start + 1, start + steps + 1) if s % POSE_EVERY == 0]


def _await_poses(client: SimClient, local: _LoopbackTopics) -> int:
    """Step until a loopback `poses` subscription has reached the server; return the step."""
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        step = int(client.step(POSE_EVERY)["step"])
        if any(topic == "poses" for topic, _ in local.drain()):
            return step
    raise AssertionError("the poses subscription never reached the server")


class _LoopbackTopics:
    """A subscriber on the server's loopback topics port, as `drcsim watch` connects."""

    def __init__(self, port: int) -> None:
        self.context = zmq.Context()
        self.sock = self.context.socket(zmq.SUB)
        self.sock.linger = 0
        self.sock.connect(f"tcp://127.0.0.1:{port + LOCAL_PORT_OFFSET}")

    def subscribe(self, topic: str) -> None:
        self.sock.setsockopt(zmq.SUBSCRIBE, topic.encode())

    def drain(self) -> list[tuple[str, dict[str, Any]]]:
        received = []
        while self.sock.poll(300):
            topic, payload = self.sock.recv_multipart()
            received.append((topic.decode(), msgpack.unpackb(payload, raw=False)))
        return received

    def __enter__(self) -> _LoopbackTopics:
        return self

    def __exit__(self, *_: object) -> None:
        self.sock.close(linger=0)
        self.context.term()


class _Output(io.StringIO):
    """What watch prints, with an event set at the first line."""

    def __init__(self) -> None:
        super().__init__()
        self.written = threading.Event()

    def write(self, text: str) -> int:
        self.written.set()
        return super().write(text)


def test_watch_prints_frames_at_its_rate_and_score_events(server: ServerFactory) -> None:
    _, port = server("vrc_task_2", "1")
    out = _Output()
    follower = threading.Thread(target=watch, args=(port, 10.0, 5.0, out))
    follower.start()
    with SimClient("127.0.0.1", port) as client:
        for _ in range(50):  # until watch has subscribed and printed a frame
            if out.written.wait(0.2):
                break
            client.step(100)
        start = client.state()["t"]
        client.step(1000)
        client.stop()
    follower.join()
    lines = [json.loads(line) for line in out.getvalue().splitlines()]
    times = [line["frame"]["t"] for line in lines if "frame" in line]
    assert all(b - a >= 0.099 for a, b in itertools.pairwise(times))
    # frames every 33 steps, at most one per 0.1 s: one every 0.132 s of the 1 s stepped
    assert 7 <= len([t for t in times if t > start]) <= 8
    assert any(line.get("score", {}).get("event") == "run_end" for line in lines)


def test_poses_command_prints_scene_then_frames(tmp_path: Path, capsys: Any) -> None:
    sim = Simulation("vrc_task_3", "1", RunOptions(log_dir=tmp_path / "run"))
    sim.step(300)
    sim.close()
    assert main(["poses", str(tmp_path / "run"), "--every", "10"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines[0]["scene"]["roles"]["robot"] == sim.scene.robot
    assert [line["frame"]["step"] for line in lines[1:]] == [100, 200, 300]
