"""csrouter's contract with the orchestrator: its commands, exit codes and counters schema.

The orchestrator runs `csrouter COMMAND` on the router over SSH and imports this module
(standard library only) rather than re-declaring any of it.
"""

from __future__ import annotations

from typing import Any

from csrouter.bandwidth_log import DIRECTIONS
from csrouter.config import DEFAULT_BANDWIDTH_LOG, MAX_LATENCY_MS

# Commands of the csrouter CLI that drive a run; the daemon's control socket takes the same ops.
ARM, DISARM, COUNTERS, STATUS = "arm", "disarm", "counters", "status"
LOG_PATH = "log-path"
# `run-log --run-id ID --from EPOCH --to EPOCH`: print the run's bandwidth log cut to that span
RUN_LOG = "run-log"

# Exit codes: 0 done (status: healthy).
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_DAEMON_DOWN = 3
EXIT_UNHEALTHY = 4  # status: the daemon runs but reports faults (in its --json answer)

# The counters (`counters --json`, `disarm --json`): one object per direction, each with
# cap_bits, remaining_bits, spent, spent_at (UTC ISO 8601, null while not spent) and the
# "accepted" and "dropped" totals (packets, ip_bytes, payload_bytes). Caps count TCP/UDP
# payload bits.

BANDWIDTH_LOG = DEFAULT_BANDWIDTH_LOG
__all__ = ["BANDWIDTH_LOG", "DIRECTIONS", "MAX_LATENCY_MS"]


def arm_args(
    latency_ms: int, uplink_bits: int | None, downlink_bits: int | None, run_id: str
) -> list[str]:
    """Return the arguments of `csrouter arm` for a run's latency and caps."""
    args = [ARM, "--latency-ms", str(latency_ms), "--run-id", run_id]
    if uplink_bits is not None:
        args += ["--uplink-bits", str(uplink_bits)]
    if downlink_bits is not None:
        args += ["--downlink-bits", str(downlink_bits)]
    return args


def run_log_args(run_id: str, started_at: float, ended_at: float) -> list[str]:
    """Return the arguments of `csrouter run-log` for a run's simulator span (epoch seconds)."""
    return [RUN_LOG, "--run-id", run_id, "--from", f"{started_at:.3f}", "--to", f"{ended_at:.3f}"]


def payload_bits_used(counters: dict[str, Any]) -> dict[str, int]:
    """Return each direction's accepted payload, in bits, from a counters answer."""
    return {d: 8 * int(counters[d]["accepted"]["payload_bytes"]) for d in DIRECTIONS}


def spent_at(counters: dict[str, Any]) -> dict[str, str | None]:
    """Return when each direction's cap was spent (ISO 8601), None where it was not."""
    return {d: counters[d].get("spent_at") for d in DIRECTIONS}
