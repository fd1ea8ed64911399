"""Control a constellation's router over SSH: arm a run's limits, read counters, disarm, logs.

These run `csrouter` on the router (the daemon the router's deploy plan installs: the VPN
path's added latency, per-direction accounting, bit caps and the bandwidth log); its
commands, exit codes and counters schema are csrouter's own (csrouter.protocol).
"""

from __future__ import annotations

import json
import math
import shlex
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import PurePosixPath
from typing import Any

from csrouter import protocol

from cloudsim.errors import CloudSimError
from constellations.plans.router import CSROUTER_COMMAND
from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget

BANDWIDTH_LOG = protocol.BANDWIDTH_LOG
CONTROL_TIMEOUT = 30
MAX_LINE_WAIT_S = 1.5


class RouterError(CloudSimError):
    """The router did not do what was asked (daemon down, bad answer)."""


@dataclass(frozen=True)
class Limits:
    """A run's network shaping: latency each way and caps per direction, in bits."""

    latency_ms: int
    uplink_bits: int
    downlink_bits: int

    def __post_init__(self) -> None:
        if not 0 <= self.latency_ms <= protocol.MAX_LATENCY_MS:
            raise ValueError(
                f"latency_ms must be between 0 and {protocol.MAX_LATENCY_MS}, got {self.latency_ms}"
            )
        if self.uplink_bits < 0 or self.downlink_bits < 0:
            raise ValueError("caps must not be negative")


def _csrouter(executor: SSHExecutor, router: SSHTarget, *args: str) -> str:
    command = " ".join([CSROUTER_COMMAND, *map(shlex.quote, args)])
    try:
        return executor.run(router, command, timeout=CONTROL_TIMEOUT).stdout
    except SSHError as exc:
        raise RouterError(f"router: {' '.join(args[:1])} failed: {exc}") from exc


def arm(executor: SSHExecutor, router: SSHTarget, limits: Limits, run_id: str) -> None:
    """Set the run's latency and caps, zero the counters, start a new bandwidth log."""
    args = protocol.arm_args(limits.latency_ms, limits.uplink_bits, limits.downlink_bits, run_id)
    _csrouter(executor, router, *args)


def ensure_armed(executor: SSHExecutor, router: SSHTarget, limits: Limits, run_id: str) -> bool:
    """Arm the run unless the router is armed for it already; return whether it armed now.

    A fact first, then the change (a resumed start must find the run counting and leave its
    counters alone); csrouter's own arm keeps them too when asked twice.
    """
    found = counters(executor, router)
    if found.get("armed") and found.get("run_id") == run_id:
        executor.log(router.name, f"{run_id} is armed already (since {found.get('armed_at')})")
        return False
    arm(executor, router, limits, run_id)
    return True


def ensure_disarmed(
    executor: SSHExecutor, router: SSHTarget, run_id: str, covering: float | None = None
) -> bool:
    """Disarm the run if the router still counts it; return whether it disarmed now.

    With `covering` (epoch seconds, the simulator's end), first wait (a second at most) until
    the router's log has a line for the second that holds it, so the log covers the run's end.
    """
    found = counters(executor, router)
    if not (found.get("armed") and found.get("run_id") == run_id):
        executor.log(router.name, f"{run_id} is not armed (any more)")
        return False
    if covering is not None and found.get("armed_at") and found.get("elapsed_s") is not None:
        armed_at = datetime.fromisoformat(found["armed_at"]).timestamp()
        line_end = armed_at + math.ceil(covering - armed_at)
        wait = line_end - (armed_at + float(found["elapsed_s"]))
        if 0 < wait <= MAX_LINE_WAIT_S:
            time.sleep(wait + 0.05)  # the router writes a line at each whole second
    disarm(executor, router)
    return True


def save_run_log(
    executor: SSHExecutor,
    router: SSHTarget,
    run_id: str,
    span: tuple[float, float],
    destination: str,
) -> None:
    """Write the run's bandwidth log, cut to the simulator's span, to `destination` on the
    router unless it is there (written whole or not at all)."""
    partial = f"{destination}.part"
    args = protocol.run_log_args(run_id, *span)
    # cut once: a resumed stop keeps the first cut (the router's log restarts at the next arm)
    command = (
        f"mkdir -p {shlex.quote(str(PurePosixPath(destination).parent))} && "
        f"(test -f {shlex.quote(destination)} || ("
        f"{CSROUTER_COMMAND} {' '.join(map(shlex.quote, args))} > {shlex.quote(partial)} && "
        f"mv {shlex.quote(partial)} {shlex.quote(destination)}))"
    )
    try:
        executor.run(router, command, timeout=600)
    except SSHError as exc:
        raise RouterError(f"router: the run's bandwidth log: {exc}") from exc


def counters(executor: SSHExecutor, router: SSHTarget) -> dict[str, Any]:
    """Return the router's counters (csrouter.protocol describes them)."""
    output = _csrouter(executor, router, protocol.COUNTERS, "--json")
    try:
        return dict(json.loads(output))
    except ValueError as exc:
        raise RouterError(f"router: counters printed something else than JSON: {exc}") from exc


def status(executor: SSHExecutor, router: SSHTarget) -> dict[str, Any]:
    """Return the daemon's status (with its faults, if any); RouterError when it is down."""
    command = f"{CSROUTER_COMMAND} {protocol.STATUS} --json"
    try:
        result = executor.run(router, command, timeout=CONTROL_TIMEOUT, check=False)
    except SSHError as exc:
        raise RouterError(f"router: status failed: {exc}") from exc
    if result.exit_code == protocol.EXIT_DAEMON_DOWN:
        raise RouterError(f"router: csrouter is down: {result.stdout.strip()}")
    if result.exit_code not in (protocol.EXIT_OK, protocol.EXIT_UNHEALTHY):
        raise RouterError(f"router: status failed (exit {result.exit_code}): {result.stderr}")
    try:
        return dict(json.loads(result.stdout))
    except ValueError as exc:
        raise RouterError(f"router: status printed something else than JSON: {exc}") from exc


def disarm(executor: SSHExecutor, router: SSHTarget) -> None:
    """End the run on the router: caps and counters stop (traffic stays delayed)."""
    _csrouter(executor, router, protocol.DISARM)
