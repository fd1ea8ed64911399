"""The network API against a real `drcsim serve` process on loopback."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest
from drcsim.client import SimClient
from drcsim.errors import ClientError
from drcsim.protocol import MAX_MESSAGE_BYTES
from drcsim.rundir import LIVE, read_live

ServerFactory = Callable[..., tuple[Any, int]]


def test_the_client_side_imports_without_the_physics_dependencies() -> None:
    # field computers install drcsim with pyzmq and msgpack only (constellations' CLIENT_ONLY)
    code = (
        "import sys\n"
        "sys.modules.update(pybullet=None, numpy=None)\n"
        "import drcsim.client, drcsim.cli, drcsim.controllers\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_hello_describes_the_run_and_lockstep_holds_time(server: ServerFactory) -> None:
    _, port = server("vrc_task_2", "3")
    with SimClient("127.0.0.1", port) as client:
        info = client.hello()
        assert info["world"] == "vrc_task_2" and info["config"] == "3"
        assert len(info["joints"]) == 30 and info["joints"][0]["name"] == "back_bkz"
        first = client.state()["step"]
        assert client.state()["step"] == first  # nothing advances without a step command
        assert client.step(25)["step"] == first + 25


def test_client_outside_allow_list_is_refused(server: ServerFactory, tmp_path: Path) -> None:
    _, port = server("vrc_task_2", "1", "--allow", "127.0.0.2", source="127.0.0.2")
    with SimClient("127.0.0.1", port, timeout_s=1.0, source="127.0.0.3") as outsider:
        with pytest.raises(ClientError, match="not allowed"):
            outsider.hello()
    with SimClient("127.0.0.1", port, source="127.0.0.2") as insider:
        assert insider.hello()["ok"]
    log = (tmp_path / "server-0.log").read_text()
    assert "refused connection from 127.0.0.3" in log


def test_malformed_and_oversized_messages_are_rejected_and_the_run_goes_on(
    server: ServerFactory, tmp_path: Path
) -> None:
    _, port = server()
    with SimClient("127.0.0.1", port) as client:
        before = client.step(10)["step"]
        bad_frames = [
            [b"\xc1 definitely not msgpack"],
            [msgpack.packb([1, 2, 3])],
            [msgpack.packb({"op": "launch_missiles"})],
            [msgpack.packb({"op": "joints", "position": {"no_such_joint": 1.0}})],
            [msgpack.packb({"op": "joints", "position": {"l_leg_kny": float("nan")}})],
            [msgpack.packb({"op": "step", "steps": -5})],
            [msgpack.packb({"op": "behaviour", "name": "walk", "pose": "north"})],
            [b"a", b"b", b"c"],
            [b"\x00" * (MAX_MESSAGE_BYTES + 1)],
        ]
        for frames in bad_frames:
            reply = client.send_raw(frames)
            assert reply["ok"] is False and reply["error"]
        assert client.step(10)["step"] == before + 10
        assert client.behaviour("walk", pose=[1.0, 0.0, 0.0])["ok"]
    log = (tmp_path / "server-0.log").read_text()
    # A line for the first; those within the next second are counted, not logged one by one.
    assert log.count("rejected message") == 1 and "not a msgpack message" in log


def test_sensors_are_published_only_to_subscribers(server: ServerFactory) -> None:
    _, port = server(
        "vrc_task_2",
        "1",
        "--sensor",
        "camera_width=64",
        "--sensor",
        "camera_height=48",
        "--sensor",
        "lidar_beams=90",
        "--sensor",
        "camera_stereo=true",
    )
    with SimClient("127.0.0.1", port) as client:
        client.step(500)  # the robot settles on its feet (the walker lowers the pelvis)
        client.subscribe("imu", "camera", "lidar", "score")
        deadline = time.monotonic() + 20
        seen: dict[str, dict] = {}
        while len(seen) < 3 and time.monotonic() < deadline:
            client.step(100)
            while (received := client.receive(0.05)) is not None:
                seen.setdefault(received[0], received[1])
        assert {"imu", "camera", "lidar"} <= set(seen)
        assert len(seen["camera"]["data"]) == len(seen["camera"]["right"]) == 64 * 48 * 3
        assert len(seen["lidar"]["ranges"]) == 90 * 4
        assert abs(seen["imu"]["linear_acceleration"][2] - 9.81) < 1.0
        assert "joint_states" not in seen and "contact" not in seen


def test_real_time_mode_advances_on_its_own_and_refuses_step(server: ServerFactory) -> None:
    process, port = server("vrc_task_2", "1", lockstep=False)
    with SimClient("127.0.0.1", port) as client:
        client.subscribe("clock")
        first = client.wait_for("clock")
        later = client.wait_for("clock", lambda m: m["t"] >= first["t"] + 0.5)
        assert later["step"] > first["step"]
        reply = client.request({"op": "step", "steps": 1})
        assert reply["ok"] is False and "lock-step" in reply["error"]
        client.stop()
    assert process.wait(timeout=30) == 0


def test_a_real_time_run_stopped_by_sigterm_is_logged_and_replays(
    server: ServerFactory, tmp_path: Path
) -> None:
    from drcsim.replay import replay

    process, port = server("vrc_task_2", "2", lockstep=False, logs=True)
    with SimClient("127.0.0.1", port) as client:
        client.subscribe("clock")
        client.behaviour("walk", pose=[2.0, 0.5, 0.0])
        middle = client.wait_for("clock", lambda m: m["t"] >= 0.3)
        client.joints(position={"l_arm_shx": -0.4})
        later = client.wait_for("clock", lambda m: m["t"] >= middle["t"] + 0.5)
        # the live figures a supervisor reads over SSH follow the simulated time
        live = _live_once(tmp_path / "run-0", lambda f: f["sim_time"] >= later["t"])
        assert live["ended"] is False and live["score"] == 0 and live["rtf"] > 0
    process.terminate()
    assert process.wait(timeout=30) == 0
    final = json.loads((tmp_path / "run-0" / "final.json").read_text())
    assert final["end_reason"] == "closed" and final["step"] >= 800
    assert replay(tmp_path / "run-0").final_digest == final["state_sha256"]


def _live_once(folder: Path, wanted: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    """Return the run's live figures once they are as wanted (rewritten twice a second)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        path = folder / LIVE
        figures = read_live(path.read_text()) if path.exists() else None
        if figures is not None and wanted(figures):
            return figures
        time.sleep(0.1)  # polling a file the simulator rewrites: nothing to await
    raise AssertionError(f"{folder / LIVE} never showed the wanted figures")


def test_the_readmes_client_example_runs_as_written(server: ServerFactory) -> None:
    _, port = server("vrc_task_2", "1")
    with SimClient("127.0.0.1", port) as sim:
        info = sim.hello()
        sim.subscribe("imu", "joint_states")
        assert sim.behaviour("walk", pose=[4.0, 0.0, 0.0])["ok"]
        sim.joints(position={"neck_ry": 0.3})  # the neck is the team's while the walker walks
        for _ in range(5):
            state = sim.step(100)
    neck = [j["name"] for j in info["joints"]].index("neck_ry")
    assert abs(state["joints"]["position"][neck] - 0.3) < 0.1  # the estimate's, noisy
    assert state["behaviour"]["mode"] == "walk" and state["score"]["falls"] == 0


def _await_line(path: Path, text: str, timeout_s: float = 20.0) -> str:
    """Return the server's log once it holds `text` (it settles bursts once a second)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        log = path.read_text()
        if text in log:
            return log
        time.sleep(0.1)  # polling a file another process writes: nothing to await
    raise AssertionError(f"{path} never said {text!r}")


def test_a_flooding_client_is_rate_limited_with_one_line_per_burst(
    server: ServerFactory, tmp_path: Path
) -> None:
    import zmq

    process, port = server("vrc_task_2", "1", lockstep=False)
    context = zmq.Context()
    flooder = context.socket(zmq.DEALER)
    flooder.linger = 0
    flooder.sndhwm = 0
    flooder.connect(f"tcp://127.0.0.1:{port}")
    try:
        for _ in range(20_000):  # bad frames as fast as it can, never reading a reply
            flooder.send(b"\xc1 not msgpack")
        with SimClient("127.0.0.1", port) as client:
            client.subscribe("clock")
            assert client.hello()["ok"]  # a well-behaved client is still served
            first = client.wait_for("clock")
            assert client.wait_for("clock", lambda m: m["t"] >= first["t"] + 0.5)
            log = _await_line(tmp_path / "server-0.log", "rate-limited 127.0.0.1")
            assert log.count("rate-limited") == 1 and log.count("rejected message") <= 3
            client.stop()
    finally:
        flooder.close()
        context.term()
    assert process.wait(timeout=30) == 0


def test_parameters_out_of_their_range_are_refused_with_the_range(server: ServerFactory) -> None:
    _, port = server("vrc_task_2", "1")
    with SimClient("127.0.0.1", port) as client:
        info = client.hello()
        assert info["ranges"]["walk.step_length"] == [0.02, 0.5]
        for params, words in (
            ({"step_length": 100.0}, "walk.step_length must be in 0.02..0.5 m, not 100"),
            ({"step_time": 1e-6}, "walk.step_time must be in 0.3..2 s"),
        ):
            reply = client.request({"op": "behaviour", "name": "walk", "pose": [1, 0, 0], **params})
            assert reply["ok"] is False and words in reply["error"]
        reply = client.request({"op": "joints", "position": {"l_arm_shx": 5.0}})
        assert reply["ok"] is False and "position.l_arm_shx must be in" in reply["error"]
        state = client.step(100)
        assert state["behaviour"]["mode"] == "stand"  # nothing changed
        assert client.behaviour("walk", pose=[1, 0, 0], step_length=0.5, step_time=0.3)["ok"]
