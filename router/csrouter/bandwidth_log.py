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
    if record.get("event") == "disarmed":
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
