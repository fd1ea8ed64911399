"""A run armed twice goes on counting; its log is cut to the simulator's span (no hosts)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from csrouter.bandwidth_log import read_bandwidth_log, run_span_lines
from csrouter.cli import main
from csrouter.config import RouterConfig
from csrouter.ocu_path import OcuPath
from csrouter.packets import PacketSize
from csrouter.protocol import run_log_args


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


def test_arming_the_armed_run_again_keeps_its_counters_and_log(tmp_path: Path) -> None:
    clock = Clock()
    path = OcuPath(router_config(tmp_path), monotonic=clock, wall=clock)
    assert path.arm(100, 8000, None, "run-7")["already_armed"] is False
    path.run.meters["uplink"].admit(PacketSize(1028, 500))
    clock.now += 2.5
    path.service()
    again = path.arm(100, 8000, None, "run-7")  # a resumed start
    assert again["already_armed"] is True and again["uplink"]["remaining_bits"] == 4000
    assert again["armed_at"] == path.counters()["armed_at"] and again["elapsed_s"] == 2.5
    records = [json.loads(line) for line in (tmp_path / "bandwidth.log").read_text().splitlines()]
    assert [r.get("event") for r in records].count("armed") == 1
    # another run is a new arm: counters at zero
    assert path.arm(100, 8000, None, "run-8")["uplink"]["remaining_bits"] == 8000
    path.save_on_exit()


def _log(tmp_path: Path, before_s: float, after_s: float) -> tuple[Path, float, float]:
    """Arm, run `before_s` idle seconds, 10 s of simulator, `after_s` more, disarm."""
    clock = Clock()
    config = router_config(tmp_path)
    path = OcuPath(config, monotonic=clock, wall=clock)
    path.arm(0, 80_000, None, "run-3")
    started = clock.now + before_s
    for _ in range(int((before_s + 10 + after_s) * 2)):
        clock.now += 0.5
        if started <= clock.now <= started + 10:
            path.run.meters["uplink"].admit(PacketSize(128, 100))
        path.service()
    path.disarm()
    path.log.close()
    return Path(config.bandwidth_log), started, started + 10


def test_the_run_log_is_one_line_a_second_from_the_simulators_start_to_its_end(
    tmp_path: Path,
) -> None:
    # as after a crash: armed 36 s before the simulator started, disarmed 49 s after its end
    log, started, ended = _log(tmp_path, 36.0, 49.0)
    cut = [
        json.loads(line)
        for line in run_span_lines(log.read_text().splitlines(), "run-3", started, ended)
    ]
    assert cut[0]["event"] == "armed" and cut[-1]["event"] == "run_span"
    lines = cut[1:-1]
    for direction in ("uplink", "downlink"):
        seconds = [r["second"] for r in lines if r["direction"] == direction]
        assert seconds == list(range(1, 11))
    assert {r["router_second"] for r in lines} == set(range(37, 47))
    usage = read_bandwidth_log(json.dumps(r) for r in cut)
    assert usage["uplink"].used_bits == 8 * 100 * 21 and len(usage["uplink"].bits_per_second) == 10
    assert usage["uplink"].remaining_bits == 80_000 - 8 * 100 * 21
    assert run_span_lines(log.read_text().splitlines(), "run-4", started, ended) == []


def test_the_run_log_command_prints_the_cut_and_refuses_an_unknown_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, started, ended = _log(tmp_path, 1.0, 1.0)
    config = tmp_path / "router.json"
    config.write_text(
        json.dumps(
            {
                "lan_subnet": "10.0.0.0/24",
                "bandwidth_log": str(log),
                "state_file": str(tmp_path / "state.json"),
                "socket": str(tmp_path / "control.sock"),
            }
        )
    )
    assert main(["--config", str(config), *run_log_args("run-3", started, ended)]) == 0
    assert main(["--config", str(config), *run_log_args("run-9", started, ended)]) == 1
    printed = capsys.readouterr()
    assert len(printed.out.splitlines()) == 1 + 2 * 10 + 1 and "run-9" in printed.err
