"""The daemon's configuration, saved state and bandwidth log files (no hosts, no queues)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from csrouter.bandwidth_log import BandwidthLog
from csrouter.config import RouterConfig, check_cap, check_latency, load_config
from csrouter.control import ControlServer, request
from csrouter.errors import ConfigError, ControlError, DaemonUnavailable
from csrouter.ocu_path import OcuPath
from csrouter.packets import PacketSize
from csrouter.run import Run, SavedState


def test_the_configuration_is_checked(tmp_path: Path) -> None:
    path = tmp_path / "router.json"
    path.write_text(json.dumps({"lan_subnet": "10.0.0.0/24", "vpn_network": "10.8.0.0/24"}))
    assert load_config(path).vpn_device == "tun-ocu"
    for bad, message in (
        ({"lan_subnet": "10.0.0.300/24"}, "not a network"),
        ({"lan_subnet": "10.0.0.0/24", "uplink_queue": 1}, "distinct"),
        ({"lan_subnet": "10.0.0.0/24", "vpn_device": "tun0; rm -rf /"}, "interface name"),
        ({"lan_subnet": "10.0.0.0/24", "colour": "red"}, "unknown"),
        ({}, "needs lan_subnet"),
    ):
        path.write_text(json.dumps(bad))
        with pytest.raises(ConfigError, match=message):
            load_config(path)


def test_latency_and_caps_are_bounded() -> None:
    assert check_latency(0) == 0 and check_latency(2000) == 2000
    for bad in (-1, 2001, 2.5, True):
        with pytest.raises(ConfigError):
            check_latency(bad)  # type: ignore[arg-type]
    assert check_cap("uplink_bits", None) is None and check_cap("uplink_bits", 0) == 0
    with pytest.raises(ConfigError, match="uplink_bits"):
        check_cap("uplink_bits", -8)


def test_a_saved_run_resumes_with_its_counts_and_spent_state(tmp_path: Path) -> None:
    run = Run.arm(latency_ms=250, uplink_bits=8000, downlink_bits=None, run_id="r", now=100.0)
    run.meters["uplink"].admit(PacketSize(1028, 1000))
    run.meters["uplink"].admit(PacketSize(28, 1))  # does not fit: spent
    run.meters["uplink"].spent_at = "2026-11-22T20:00:00.000+00:00"  # the daemon stamps it
    SavedState(run, False, 101.0, ["earlier fault"]).write(str(tmp_path / "state.json"))
    saved = SavedState.read(str(tmp_path / "state.json"))
    assert saved is not None and not saved.clean_exit and saved.faults == ["earlier fault"]
    assert saved.run.counters(102.0) == run.counters(102.0)
    assert saved.run.meters["uplink"].spent and saved.run.counters(102.0)["elapsed_s"] == 2.0
    assert saved.run.counters(102.0)["uplink"]["spent_at"] == "2026-11-22T20:00:00.000+00:00"
    assert SavedState.read(str(tmp_path / "missing.json")) is None


def test_the_bandwidth_log_restarts_and_keeps_the_previous_run(tmp_path: Path) -> None:
    log = BandwidthLog(str(tmp_path / "logs" / "bandwidth.log"))
    log.append([{"run": 1}])
    log.restart()
    log.append([{"run": 2}, {"run": 2, "second": 1}])
    log.close()
    assert (tmp_path / "logs" / "bandwidth.log.1").read_text() == '{"run":1}\n'
    lines = (tmp_path / "logs" / "bandwidth.log").read_text().splitlines()
    assert [json.loads(line)["run"] for line in lines] == [2, 2]


def test_router_config_defaults_are_the_documented_ones() -> None:
    config = RouterConfig(lan_subnet="10.0.0.0/24")
    assert (config.uplink_queue, config.downlink_queue, config.default_latency_ms) == (0, 1, 250)


class Clock:
    """A clock the test moves by hand (both monotonic and wall time)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def router_config(tmp_path: Path) -> RouterConfig:
    return RouterConfig(
        lan_subnet="10.0.0.0/24",
        bandwidth_log=str(tmp_path / "bandwidth.log"),
        state_file=str(tmp_path / "state.json"),
        socket=str(tmp_path / "control.sock"),
    )


def test_an_armed_run_logs_every_whole_second_and_its_end(tmp_path: Path) -> None:
    clock = Clock()
    path = OcuPath(router_config(tmp_path), monotonic=clock, wall=clock)
    path.arm(100, 8000, None, "r1")
    clock.now += 3.5
    path.service()
    final = path.disarm()
    path.save_on_exit()
    records = [json.loads(line) for line in (tmp_path / "bandwidth.log").read_text().splitlines()]
    assert [r.get("event") or r["direction"] for r in records] == [
        "armed", *["uplink", "downlink"] * 3, "disarmed"
    ]  # fmt: skip
    assert records[1]["cap_remaining_bits"] == 8000 and final["elapsed_s"] == 3.5
    # written late (all three at once) but stamped with the second each covers
    assert [r["second"] for r in records[1:-1:2]] == [1, 2, 3]
    assert [r["time"][17:23] for r in records[1:-1:2]] == ["41.000", "42.000", "43.000"]
    assert path.counters()["last_run"] == final and not path.counters()["armed"]


def test_a_restart_after_a_crash_resumes_the_run_with_a_fault(tmp_path: Path) -> None:
    clock = Clock()
    crashed = OcuPath(router_config(tmp_path), monotonic=clock, wall=clock)
    crashed.arm(100, None, None, "r1")
    crashed.log.close()  # what dying does; no clean exit is saved
    resumed = OcuPath(router_config(tmp_path), monotonic=clock, wall=clock)
    assert resumed.run.run_id == "r1" and "unclean exit" in resumed.faults[0]
    resumed.save_on_exit()
    again = OcuPath(router_config(tmp_path), monotonic=clock, wall=clock)
    again.save_on_exit()
    # a clean stop adds no fault; the earlier one stays until the next arm
    assert again.faults == resumed.faults and again.run.armed


def test_an_unreadable_state_file_is_set_aside(tmp_path: Path) -> None:
    (tmp_path / "state.json").write_text("{not json")
    path = OcuPath(router_config(tmp_path))
    assert "unreadable" in path.faults[0] and not path.run.armed
    assert (tmp_path / "state.json.unreadable").read_text() == "{not json"


def test_the_control_socket_answers_and_reports_errors(tmp_path: Path) -> None:
    def handle(message: dict[str, Any]) -> dict[str, Any]:
        if message["op"] == "boom":
            raise ConfigError("refused")
        return {"echo": message["op"]}

    socket_path = tmp_path / "run" / "control.sock"
    server = ControlServer(str(socket_path), handle)
    server.start()
    try:
        assert request(str(socket_path), {"op": "status"}) == {"echo": "status"}
        with pytest.raises(ControlError, match="refused"):
            request(str(socket_path), {"op": "boom"})
        assert oct(socket_path.stat().st_mode & 0o777) == "0o600"
        assert oct(socket_path.parent.stat().st_mode & 0o777) == "0o700"
    finally:
        server.close()
    with pytest.raises(DaemonUnavailable, match="does not answer"):
        request(str(socket_path), {"op": "status"})
