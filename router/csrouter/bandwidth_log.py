"""The bandwidth log: JSON lines, one a second per direction while a run is armed."""

from __future__ import annotations

import json
import os
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any


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
