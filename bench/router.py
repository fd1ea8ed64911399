"""Benchmark the router's OCU path on local hosts: latency, accounting error, daemon CPU.

Boots the test lab (router, sim, OCU with the VPN up), then for idle and 1, 10 and 50 Mbit/s
of UDP load OCU->sim measures the ping round trip against 2 x 250 ms (mean, p99, and the
added part over the undelayed round trip), the accounting error in payload bytes (counted by
csrouter minus what was sent and received), and csrouter's CPU share. Needs root.
Usage: python bench/router.py [--seconds 8]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT))

from provisioners.local.driver import LocalNodeDriver  # noqa: E402
from provisioners.ssh import ConnectPolicy, InMemoryHostKeyStore, SSHExecutor  # noqa: E402
from tests.router import conftest as lab_support  # noqa: E402

LATENCY_MS = 250
PAYLOAD = 1200
PING_INTERVAL = 0.05
PORT = 5006
ICMP_CHARGE = 64  # a default ping: 56 data bytes + 8 of ICMP header


def rtts(output: str) -> list[float]:
    """Return the round trips (ms) of a ping run."""
    return [float(ms) for ms in re.findall(r"time=([\d.]+) ms", output)]


def p99(values: list[float]) -> float:
    """Return the 99th percentile (nearest rank)."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.99 * len(ordered)))]


def cpu_seconds(lab: lab_support.RouterLab) -> float:
    """Return csrouter's user+system CPU seconds so far."""
    stat = lab.run("router", "cat /proc/$(systemctl show -p MainPID --value csrouter)/stat").split(
        ")"
    )[-1]
    fields = stat.split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(lab: lab_support.RouterLab, mbit: float, seconds: float, base_ms: float) -> str:
    """Run one load level and return its report line."""
    lab.csrouter("arm", "--latency-ms", str(LATENCY_MS), "--run-id", f"bench-{mbit}")
    pings = int(seconds / PING_INTERVAL)
    sender_count, out = 0, ""
    if mbit:
        pps = mbit * 1e6 / 8 / PAYLOAD
        sender_count = int(pps * (seconds + 1))
        out = lab.start_receiver("sim", PORT, timeout=seconds + 30, idle=2)
        lab.run(
            "ocu",
            f"setsid python3 {lab_support.REMOTE_TRAFFIC} send {lab.ip('sim')} {PORT} "
            f"{sender_count} {PAYLOAD} {pps:.0f} > /dev/null 2>&1 < /dev/null &",
        )
    cpu_before, wall_before = cpu_seconds(lab), time.monotonic()
    ping = lab.run(
        "ocu",
        f"ping -n -c {pings} -i {PING_INTERVAL} -W 5 {lab.ip('sim')}",
        timeout=seconds * 3 + 30,
        check=False,
    )
    received = lab.received("sim", out, timeout=seconds + 60) if mbit else {"bytes": 0}
    cpu = (cpu_seconds(lab) - cpu_before) / (time.monotonic() - wall_before)
    counted = lab.csrouter("counters")["uplink"]["accepted"]["payload_bytes"]
    samples = rtts(ping)
    lost = pings - len(samples)
    error = counted - received["bytes"] - ICMP_CHARGE * pings
    achieved = received["bytes"] * 8 / 1e6 / (seconds + 1) if mbit else 0.0
    return (
        f"{mbit:>5} Mbit/s (got ~{achieved:5.1f}): RTT mean {statistics.mean(samples):7.2f} ms, "
        f"p99 {p99(samples):7.2f} ms (target {2 * LATENCY_MS}); added over undelayed: mean "
        f"{statistics.mean(samples) - base_ms:7.2f} ms; accounting error {error:+d} bytes "
        f"(sent {sender_count * PAYLOAD}, received {received['bytes']}, counted {counted}); "
        f"{lost} of {pings} pings lost; "
        f"csrouter CPU {100 * cpu:5.1f}% of a core"
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
    executor = SSHExecutor(InMemoryHostKeyStore(), connect_policy=ConnectPolicy(deadline=60))
    try:
        started = time.monotonic()
        lab = lab_support._build_lab(driver, executor, scratch)
        print(f"lab up with the VPN connected in {time.monotonic() - started:.1f} s")
        lab.csrouter("arm", "--latency-ms", "0", "--run-id", "base")
        base = rtts(lab.run("ocu", f"ping -n -c 40 -i {PING_INTERVAL} {lab.ip('sim')}"))
        base_ms = statistics.mean(base)
        print(f"undelayed round trip OCU->sim through the VPN: mean {base_ms:.2f} ms")
        for mbit in (0, 1, 10, 50):
            print(measure(lab, mbit, args.seconds, base_ms), flush=True)
        print(f"load average now: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    finally:
        executor.close()
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(scratch)


if __name__ == "__main__":
    main()
