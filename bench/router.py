"""Benchmark the router's OCU path on local hosts: latency, accounting error, daemon CPU.

Boots the test lab (router, sim, OCU with the VPN up), then for idle and 1, 10 and 50 Mbit/s
of UDP load OCU->sim measures UDP echo round trips OCU->sim->OCU against 2 x 250 ms (mean,
p99, and the part added over the undelayed round trip), the accounting error in payload
bytes (counted by csrouter minus what was sent and received), csrouter's CPU share and how
late csrouter itself released packets. Needs root. Usage: python -m bench.router [--seconds 8]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import ConnectPolicy, HostKeys, SSHExecutor
from tests.router import conftest as lab_support
from tests.router.traffic import PROBE_BYTES

LATENCY_MS = 250
PAYLOAD = 1200
PROBE_INTERVAL = 0.05
LOAD_PORT, ECHO_PORT = 5006, 5007


def probe(lab: lab_support.RouterLab, count: int) -> dict[str, Any]:
    """Measure UDP round trips OCU->sim->OCU (microsecond clock; ping prints whole ms)."""
    output = lab.run(
        "ocu",
        f"python3 {lab_support.REMOTE_TRAFFIC} probe {lab.ip('sim')} {ECHO_PORT} {count} "
        f"{PROBE_INTERVAL}",
        timeout=count * PROBE_INTERVAL * 3 + 30,
    )
    return dict(json.loads(output.splitlines()[-1]))


def p99(values: list[float]) -> float:
    """Return the 99th percentile (nearest rank)."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.99 * len(ordered)))]


def cpu_seconds(lab: lab_support.RouterLab) -> float:
    """Return csrouter's user+system CPU seconds so far."""
    stat = lab.run("router", "cat /proc/$(systemctl show -p MainPID --value csrouter)/stat")
    fields = stat.split(")")[-1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(lab: lab_support.RouterLab, mbit: float, seconds: float, base_ms: float) -> str:
    """Run one load level and return its report line."""
    lab.csrouter("arm", "--latency-ms", str(LATENCY_MS), "--run-id", f"bench-{mbit}")
    probes = int(seconds / PROBE_INTERVAL)
    sent, out = 0, ""
    if mbit:
        pps = mbit * 1e6 / 8 / PAYLOAD
        count = int(pps * (seconds + 1))
        sent = count * PAYLOAD
        out = lab.start_receiver("sim", LOAD_PORT, timeout=seconds + 30, idle=2)
        lab.run(
            "ocu",
            f"setsid python3 {lab_support.REMOTE_TRAFFIC} send {lab.ip('sim')} {LOAD_PORT} "
            f"{count} {PAYLOAD} {pps:.0f} > /dev/null 2>&1 < /dev/null &",
        )
    cpu_before, wall_before = cpu_seconds(lab), time.monotonic()
    result = probe(lab, probes)
    received = lab.received("sim", out, timeout=seconds + 60)["bytes"] if mbit else 0
    cpu = (cpu_seconds(lab) - cpu_before) / (time.monotonic() - wall_before)
    counted = lab.csrouter("counters")["uplink"]["accepted"]["payload_bytes"]
    late = lab.csrouter("status")["release_lateness"]
    rtts = result["rtts_ms"]
    error = counted - received - PROBE_BYTES * probes
    return (
        f"{mbit:>2} Mbit/s (got {received * 8 / 1e6 / (seconds + 1):5.1f}): RTT mean "
        f"{statistics.mean(rtts):7.2f} ms, p99 {p99(rtts):7.2f} ms, max {max(rtts):7.2f} "
        f"(target {2 * LATENCY_MS}; added over undelayed: {statistics.mean(rtts) - base_ms:.2f});"
        f" {result['lost']}/{probes} probes lost; accounting error {error:+d} B (sent {sent}, "
        f"received {received}, counted {counted}); csrouter CPU {100 * cpu:4.1f}% of a core; "
        f"csrouter late by mean/max {late['uplink']['mean_ms']:.3f}/"
        f"{late['uplink']['max_ms']:.1f} ms up, {late['downlink']['mean_ms']:.3f}/"
        f"{late['downlink']['max_ms']:.1f} ms down"
    )


def main() -> None:
    """Build the lab, run every load level, print one line each, tear everything down."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0)
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="crbench-"))
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=f"crb{os.getpid() % 100000}",
        subnet_pool="10.217.0.0/16",
        public_cidr="198.18.17.0/24",
    )
    executor = SSHExecutor(HostKeys(), connect_policy=ConnectPolicy(deadline=60))
    try:
        started = time.monotonic()
        lab = lab_support._build_lab(driver, executor, scratch)
        print(f"lab up with the VPN connected in {time.monotonic() - started:.1f} s")
        lab.csrouter("arm", "--latency-ms", "0", "--run-id", "base")
        lab.start_echo("sim", ECHO_PORT, idle=60)
        base_ms = statistics.mean(probe(lab, 40)["rtts_ms"])
        print(f"undelayed UDP round trip OCU->sim through the VPN: mean {base_ms:.2f} ms")
        for mbit in (0, 1, 10, 50):
            print(measure(lab, mbit, args.seconds, base_ms), flush=True)
        print(f"load average now: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    finally:
        lab_support.tear_down(driver, executor, scratch)


if __name__ == "__main__":
    main()
