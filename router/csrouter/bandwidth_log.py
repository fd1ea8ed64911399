"""The bandwidth log: JSON lines, one a second per direction while a run is armed.

The writer (the daemon) and the reader (the orchestrator, for a run's figures and plots) are
both here, so the format has one owner.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any

UPLINK = "uplink"  # OCU -> LAN
DOWNLINK = "downlink"  # LAN -> OCU
DIRECTIONS = (UPLINK, DOWNLINK)


def utc_iso(epoch: float) -> str:
    """Return an epoch time as ISO 8601 UTC with milliseconds."""
    return datetime.fromtimestamp(epoch, tz=UTC).isoformat(timespec="milliseconds")


class BandwidthLog:
    """An append-only JSON-lines file, started afresh (previous kept as .1) at each arm."""

    def __init__(self, path: str) -> None:
        self.path = Path(path)
        self._handle: IO[str] | None = None

    def restart(self) -> None:
        """Keep the previous log as PATH.1 and open an empty one."""
        self.close()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists():
            os.replace(self.path, self.path.with_name(self.path.name + ".1"))
        self._open()

    def append(self, records: list[dict[str, Any]]) -> None:
        """Write records, one JSON object a line, and flush them to the file."""
        if self._handle is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._open()
        assert self._handle is not None
        for record in records:
            self._handle.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._handle.flush()

    def close(self) -> None:
        """Close the file (appending later reopens it)."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None

    def _open(self) -> None:
        descriptor = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o640)
        self._handle = os.fdopen(descriptor, "a", buffering=1 << 16)


@dataclass
class Bandwidth:
    """Bits per second of one direction, second by second from the run's arm, and its totals."""

    bits_per_second: list[int] = field(default_factory=list)
    used_bits: int = 0
    cap_bits: int | None = None
    remaining_bits: int | None = None
    spent_at: datetime | None = None  # from the final counters: when the cap was spent


# A log's seconds past this are not a run's (runs last minutes): such a line is malformed, and
# keeping it would grow the per-second list to its size.
MAX_SECOND = 7 * 24 * 3600


def read_bandwidth_log(lines: Iterable[str]) -> dict[str, Bandwidth]:
    """Return each direction's per-second bits from the router's bandwidth log (JSON lines).

    Lines that are not the log's records (torn, or malformed in a copy uploaded from elsewhere)
    are skipped: the rest of the log still reads.
    """
    result = {d: Bandwidth() for d in DIRECTIONS}
    start: datetime | None = None
    for line in lines:
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            if isinstance(record, dict):
                start = _read_record(record, result, start)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError):
            continue  # e.g. a torn last line of a log copied while the router wrote it
    return result


def _read_record(
    record: dict[str, Any], result: dict[str, Bandwidth], start: datetime | None
) -> datetime | None:
    """Add one record to the directions' series; return the arm time known after it."""
    if record.get("event") == "armed":
        armed = datetime.fromisoformat(record["time"])
        caps = {d: (record.get("caps_bits") or {}).get(d) for d in DIRECTIONS}
        caps = {d: None if cap is None else int(cap) for d, cap in caps.items()}
        for direction in DIRECTIONS:
            result[direction].cap_bits = caps[direction]
        return armed
    if record.get("event") in ("disarmed", "run_span"):
        for direction in DIRECTIONS:
            when = ((record.get("counters") or {}).get(direction) or {}).get("spent_at")
            result[direction].spent_at = datetime.fromisoformat(when) if when else None
        return start
    name = record.get("direction")
    if name not in result or "bytes" not in record:
        return start
    if "second" in record:  # line N covers N-1..N s after the arm
        second = max(0, int(record["second"]) - 1)
    else:
        moment = datetime.fromisoformat(record["time"])
        start = start or moment
        second = max(0, round((moment - start).total_seconds()) - 1)
    if second > MAX_SECOND:
        raise ValueError(f"second {second} is past any run")
    bits, used = 8 * int(record["bytes"]), 8 * int(record.get("cumulative_bytes", 0))
    remaining = record.get("cap_remaining_bits")
    series = result[name]
    series.bits_per_second.extend([0] * (second + 1 - len(series.bits_per_second)))
    series.bits_per_second[second] += bits
    series.used_bits = used
    series.remaining_bits = None if remaining is None else int(remaining)
    return start


def run_span_lines(
    lines: Iterable[str], run_id: str, started_at: float, ended_at: float
) -> list[str]:
    """Return a run's bandwidth log cut to the simulator's span: its `armed` event, then one
    line a second per direction for every second from `started_at` to `ended_at` (epoch
    seconds), renumbered from 1, then a `run_span` event saying where the cut was made.

    The router's log runs from the arm to the disarm; a crash can put either a good while
    away from the simulator's start or end, and those seconds are not the run's. A line
    covers the second before its time, so the kept lines are those whose second overlaps the
    span; each keeps its arm-relative number as `router_second`.
    """
    armed: dict[str, Any] | None = None
    kept: list[dict[str, Any]] = []
    disarmed: dict[str, Any] | None = None
    for line in lines:
        try:
            record = json.loads(line)
        except ValueError:
            continue  # a torn line (the daemon killed mid-write)
        if not isinstance(record, dict) or record.get("run_id") != run_id:
            continue
        if record.get("event") == "armed":
            armed, kept, disarmed = record, [], None  # only the last arm of a run id counts
            continue
        if record.get("event") == "disarmed":
            disarmed = record
            continue
        if "second" not in record or "direction" not in record:
            continue
        end_of_second = datetime.fromisoformat(record["time"]).timestamp()
        if end_of_second > started_at and end_of_second - 1 < ended_at:
            kept.append(record)
    if armed is None:
        return []
    first = min((int(r["second"]) for r in kept), default=1)
    out = [armed]
    out += [
        {**r, "second": int(r["second"]) - first + 1, "router_second": r["second"]} for r in kept
    ]
    span: dict[str, Any] = {
        "time": utc_iso(ended_at),
        "event": "run_span",
        "run_id": run_id,
        "started_at": utc_iso(started_at),
        "ended_at": utc_iso(ended_at),
    }
    if disarmed is not None:
        # when a cap was spent counts only if it was spent within the run
        counters = disarmed.get("counters") or {}
        span["counters"] = {
            d: {"spent_at": _within((counters.get(d) or {}).get("spent_at"), ended_at)}
            for d in DIRECTIONS
        }
    out.append(span)
    return [json.dumps(record, separators=(",", ":")) for record in out]


def _within(moment: str | None, ended_at: float) -> str | None:
    if moment is None or datetime.fromisoformat(moment).timestamp() > ended_at:
        return None
    return moment
