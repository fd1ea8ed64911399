"""Control a constellation's router over SSH: arm a run's limits, read counters, disarm, logs.

These run `csrouter` on the router (the daemon the router's deploy plan installs: the VPN
path's added latency, per-direction accounting, bit caps and the bandwidth log).
"""

from __future__ import annotations

import json
import shlex
from dataclasses import dataclass
from typing import Any

from cloudsim.errors import CloudSimError
from constellations.plans.router import CSROUTER_COMMAND
from provisioners.ssh import Machine as Target
from provisioners.ssh import SSHError, SSHExecutor

BANDWIDTH_LOG = "/var/log/cloudsim/bandwidth.log"
CONTROL_TIMEOUT = 30
DAEMON_DOWN, FAULTS = 3, 4  # csrouter's exit codes (router/README.md)


class RouterError(CloudSimError):
    """The router did not do what was asked (daemon down, bad answer)."""


@dataclass(frozen=True)
class Limits:
    """A run's network shaping: latency each way and caps per direction, in bits."""

    latency_ms: int
    uplink_bits: int
    downlink_bits: int

    def __post_init__(self) -> None:
        if not 0 <= self.latency_ms <= 2000:
            raise ValueError(f"latency_ms must be between 0 and 2000, got {self.latency_ms}")
        if self.uplink_bits < 0 or self.downlink_bits < 0:
            raise ValueError("caps must not be negative")


def _csrouter(executor: SSHExecutor, router: Target, *args: str) -> str:
    command = " ".join([CSROUTER_COMMAND, *map(shlex.quote, args)])
    try:
        return executor.run(router, command, timeout=CONTROL_TIMEOUT).stdout
    except SSHError as exc:
        raise RouterError(f"router: {' '.join(args[:1])} failed: {exc}") from exc


def arm(executor: SSHExecutor, router: Target, limits: Limits, run_id: str) -> None:
    """Set the run's latency and caps, zero the counters, start a new bandwidth log."""
    _csrouter(
        executor,
        router,
        "arm",
        "--latency-ms",
        str(limits.latency_ms),
        "--uplink-bits",
        str(limits.uplink_bits),
        "--downlink-bits",
        str(limits.downlink_bits),
        "--run-id",
        run_id,
    )


def counters(executor: SSHExecutor, router: Target) -> dict[str, Any]:
    """Return the router's counters (per direction: bytes, payload bytes, cap left)."""
    output = _csrouter(executor, router, "counters", "--json")
    try:
        return dict(json.loads(output))
    except ValueError as exc:
        raise RouterError(f"router: counters printed something else than JSON: {exc}") from exc


def status(executor: SSHExecutor, router: Target) -> dict[str, Any]:
    """Return the daemon's status (with its faults, if any); RouterError when it is down."""
    command = f"{CSROUTER_COMMAND} status --json"
    try:
        result = executor.run(router, command, timeout=CONTROL_TIMEOUT, check=False)
    except SSHError as exc:
        raise RouterError(f"router: status failed: {exc}") from exc
    if result.exit_code == DAEMON_DOWN:
        raise RouterError(f"router: csrouter is down: {result.stdout.strip()}")
    if result.exit_code not in (0, FAULTS):
        raise RouterError(f"router: status failed (exit {result.exit_code}): {result.stderr}")
    try:
        return dict(json.loads(result.stdout))
    except ValueError as exc:
        raise RouterError(f"router: status printed something else than JSON: {exc}") from exc


def disarm(executor: SSHExecutor, router: Target) -> None:
    """End the run on the router: caps and counters stop (traffic stays delayed)."""
    _csrouter(executor, router, "disarm")
