"""Benchmarks and the headless self-test: real-time factor per world, command round trip."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from drcsim.client import SimClient
from drcsim.engine import RunOptions, Simulation
from drcsim.errors import ClientError, DrcsimError
from drcsim.protocol import check_command, encode
from drcsim.scene import TIMESTEP
from drcsim.sensors import SENSOR_TOPICS, SensorSettings
from drcsim.worlds import WORLD_NAMES

BENCH_TOPICS = set(SENSOR_TOPICS)  # every sensor, the stereo pair included
TARGET_RTF = 1.5  # issue 13: with every sensor subscribed, in every world, on one core
# The target is checked against the RTF by the process's own CPU time, which is what one
# uncontended core gives; the wall-clock RTF moves with whatever else loads the machine.
TARGET_ON = "cpu_rtf"
SPLIT_PARTS = ("physics", "behaviours", "controller", *SENSOR_TOPICS)


class CostSplit:
    """Charges the CPU time of a simulation's steps to their parts (`drcsim bench --split`)."""

    def __init__(self, sim: Simulation) -> None:
        self.seconds = dict.fromkeys(SPLIT_PARTS, 0.0)
        # Wrapping the instances' own attributes leaves the code it measures as it is.
        self._wrap(sim.client, "stepSimulation", "physics")
        self._wrap(sim.behaviours, "apply", "behaviours")
        self._wrap(sim.controller, "apply", "controller")
        self._wrap(sim.sensors, "compute", None)

    def _wrap(self, owner: object, name: str, part: str | None) -> None:
        """Time `owner.name`, charged to `part` (None: to its first argument, a sensor topic)."""
        inner = getattr(owner, name)

        def timed(*args: Any) -> Any:
            started = time.process_time()
            try:
                return inner(*args)
            finally:
                self.seconds[part or args[0]] += time.process_time() - started

        setattr(owner, name, timed)

    def ms_per_sim_s(self, cpu_s: float, sim_s: float) -> dict[str, float]:
        """Return CPU milliseconds per simulated second of each part and of the rest."""
        parts = {**self.seconds, "other": cpu_s - sum(self.seconds.values())}
        return {part: round(1000 * spent / sim_s, 1) for part, spent in parts.items()}


def measure_rtf(
    world: str,
    config: str,
    seconds: float,
    sensors: bool,
    split: bool = False,
) -> dict[str, Any]:
    """Step `world` for `seconds` of simulated time (the walker walking); return RTF and falls.

    `rtf` is by wall clock, `cpu_rtf` by the process's CPU time over the same steps; `split`
    adds where that CPU time went (the timing itself costs about 1% more).
    """
    published = {"bytes": 0}

    def publish(_: str, message: dict[str, Any]) -> None:
        published["bytes"] += len(encode(message))  # encoding is part of the sensor cost

    settings = SensorSettings(lidar_hz=40.0, camera_hz=10.0, camera_width=320, camera_height=240)
    sim = Simulation(world, config, RunOptions(sensors=settings, publish=publish))
    try:
        if sensors:
            sim.active_topics = set(BENCH_TOPICS)
        x, y, yaw = sim.spec.robot_start
        walk = {"op": "behaviour", "name": "walk", "pose": [x + 1.0, y, yaw]}
        sim.apply_command(check_command(walk))
        cost = CostSplit(sim) if split else None
        steps = round(seconds / TIMESTEP)
        started, started_cpu = time.perf_counter(), time.process_time()
        sim.step(steps)
        cpu = time.process_time() - started_cpu
        wall = time.perf_counter() - started
        row = {
            "world": world,
            "sensors": sensors,
            "sim_s": sim.sim_time,
            "wall_s": round(wall, 3),
            "cpu_s": round(cpu, 3),
            "rtf": round(sim.sim_time / wall, 3),
            "cpu_rtf": round(sim.sim_time / max(cpu, 1e-9), 3),
            "falls": sim.scorer.falls,
            "published_bytes": published["bytes"],
        }
        if cost is not None:
            row["cpu_ms_per_sim_s"] = cost.ms_per_sim_s(cpu, sim.sim_time)
        return row
    finally:
        sim.close()


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def free_port_block(count: int = 3) -> int:
    """Return the first of `count` consecutive TCP ports on 127.0.0.1 that are free right now."""
    while True:
        first = free_port()
        probes = [socket.socket() for _ in range(count - 1)]
        try:
            for offset, probe in enumerate(probes, start=1):
                probe.bind(("127.0.0.1", first + offset))
            return first
        except OSError:
            continue
        finally:
            for probe in probes:
                probe.close()


def start_server(
    world: str,
    config: str,
    extra: list[str],
    log_dir: Path | None = None,
    stderr: Path | None = None,
) -> tuple[subprocess.Popen[bytes], int]:
    """Start `drcsim serve` on loopback ports; return the process and its command port.

    The topics ports are the defaults (command port + 1 and + 2), so `drcsim watch --port`
    finds the loopback one.
    """
    port = free_port_block()
    args = [
        sys.executable,
        "-m",
        "drcsim.cli",
        "serve",
        "--world",
        world,
        "--config",
        config,
        "--bind",
        "127.0.0.1",
        "--port",
        str(port),
        *extra,
    ]
    if log_dir is not None:
        args += ["--log-dir", str(log_dir)]
    if stderr is None:
        return subprocess.Popen(args, stdout=subprocess.DEVNULL), port
    with open(stderr, "wb") as errors:
        return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=errors), port


def wait_ready(
    port: int,
    process: subprocess.Popen[bytes],
    timeout_s: float = 30.0,
    source: str | None = None,
    host: str = "127.0.0.1",
) -> None:
    """Wait until the server at host:port answers hello (or its process dies)."""
    deadline = time.monotonic() + timeout_s
    with SimClient(host, port, timeout_s=0.5, source=source) as client:
        while time.monotonic() < deadline:
            if process.poll() is not None:
                raise DrcsimError(f"server exited with {process.returncode}")
            try:
                client.hello()
                return
            except ClientError:
                continue
    raise DrcsimError("server did not become ready")


def measure_round_trip(samples: int) -> dict[str, Any]:
    """Time command-to-state round trips (step 1 in lock-step) over loopback."""
    process, port = start_server("vrc_task_2", "1", ["--lockstep"])
    try:
        wait_ready(port, process)
        with SimClient("127.0.0.1", port) as client:
            client.step(10)
            times = []
            for _ in range(samples):
                started = time.perf_counter()
                client.step(1)
                times.append(time.perf_counter() - started)
            client.stop()
        ms = np.array(times) * 1000.0
        return {
            "samples": samples,
            "p50_ms": round(float(np.percentile(ms, 50)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3),
            "max_ms": round(float(ms.max()), 3),
        }
    finally:
        process.terminate()
        process.wait(timeout=30)


def run_bench(seconds: float, samples: int, split: bool = False) -> dict[str, Any]:
    """Return every benchmark figure.

    Each world walks twice: with no sensors (the reference, measured in the same run) and
    with every sensor subscribed. A sensor row's `cpu_vs_no_sensors` is its
    CPU time over the reference's, and `meets_target` compares its `cpu_rtf` with TARGET_RTF.
    """
    load_before = os.getloadavg()
    rtf: list[dict[str, Any]] = []
    for world in WORLD_NAMES:
        reference = measure_rtf(world, "1", seconds, False, split)
        loaded = measure_rtf(world, "1", seconds, True, split)
        loaded["cpu_vs_no_sensors"] = round(loaded["cpu_s"] / max(reference["cpu_s"], 1e-9), 2)
        loaded["meets_target"] = loaded[TARGET_ON] >= TARGET_RTF
        rtf += [reference, loaded]
    load_after = os.getloadavg()
    return {
        "rtf": rtf,
        "target": {
            "rtf": TARGET_RTF,
            "on": TARGET_ON,
            "met": all(row["meets_target"] for row in rtf if row["sensors"]),
        },
        "round_trip": measure_round_trip(samples),
        "sensors": "lidar 40 Hz 1081 beams + IMU, joint states, hand contact 100 Hz"
        " + stereo camera 2x320x240 10 Hz",
        "cpu_count": os.cpu_count(),
        "load_average": {  # 1, 5 and 15 minutes, when the RTF rows started and ended
            "before": [round(v, 2) for v in load_before],
            "after": [round(v, 2) for v in load_after],
        },
    }


def selftest(
    world: str, config: str, seconds: float, sensors: bool, min_rtf: float
) -> dict[str, Any]:
    """Load a world, step it headless, and report whether it ran at the required RTF."""
    result = measure_rtf(world, config, seconds, sensors)
    result["ok"] = result["falls"] == 0 and result["rtf"] >= min_rtf
    result["min_rtf"] = min_rtf
    return result
