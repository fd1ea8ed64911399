"""A run's logs: metadata with the seed, command log, 100 Hz state log, score log, final state.

The file names and the readers an orchestrator needs are in drcsim.rundir.
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import msgpack

from drcsim.rundir import COMMANDS, FINAL, META, SCORE, STATE, WORLD


def state_digest(vector: list[float]) -> str:
    """Return a digest of a state vector's exact float64 values."""
    return hashlib.sha256(struct.pack(f"<{len(vector)}d", *vector)).hexdigest()


class RunLog:
    """Streams a run's logs to a directory; every file is appended and flushed as it goes."""

    def __init__(
        self, directory: Path, meta: dict[str, Any], world: dict[str, Any] | None = None
    ) -> None:
        directory.mkdir(parents=True, exist_ok=True)
        self.directory = directory
        (directory / META).write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
        if world is not None:  # a replay rebuilds the run from the world it was handed
            (directory / WORLD).write_text(json.dumps(world, indent=2) + "\n")
        self._commands: IO[str] = open(directory / COMMANDS, "w")
        self._state: IO[bytes] = open(directory / STATE, "wb")
        self._score: IO[str] = open(directory / SCORE, "w")
        self._state_hash = hashlib.sha256()
        self._packer = msgpack.Packer()

    def command(self, step: int, message: dict[str, Any]) -> None:
        """Record a command applied before physics step `step`."""
        self._commands.write(json.dumps({"step": step, "command": message}) + "\n")
        self._commands.flush()

    def state(self, step: int, sim_time: float, vector: list[float]) -> None:
        """Record the 100 Hz state (about 0.4 kB a record)."""
        # float32 values to look at, plus a digest of the exact float64 state to replay against.
        values = struct.pack(f"<{len(vector)}f", *vector)
        record = self._packer.pack(
            {"step": step, "t": sim_time, "state32": values, "digest": state_digest(vector)[:16]}
        )
        self._state_hash.update(record)
        self._state.write(record)

    def score(self, event: dict[str, Any]) -> None:
        """Record a score event."""
        self._score.write(json.dumps(event, sort_keys=True) + "\n")
        self._score.flush()

    def close(self, final: dict[str, Any]) -> None:
        """Write the final state and checksums, and close every file."""
        self._state.flush()
        final = {**final, "state_log_sha256": self._state_hash.hexdigest()}
        (self.directory / FINAL).write_text(json.dumps(final, indent=2, sort_keys=True) + "\n")
        for handle in (self._commands, self._state, self._score):
            handle.close()


def read_commands(directory: Path) -> Iterator[tuple[int, dict[str, Any]]]:
    """Yield (step, command) in the order they were applied."""
    with open(directory / COMMANDS) as handle:
        for line in handle:
            record = json.loads(line)
            yield int(record["step"]), record["command"]


def read_states(directory: Path) -> Iterator[dict[str, Any]]:
    """Yield the 100 Hz state records."""
    with open(directory / STATE, "rb") as handle:
        yield from msgpack.Unpacker(handle, raw=False)
