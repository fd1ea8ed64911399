"""Claims of servers and networks: one document in the providers' JSON state store."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from provisioners.providers.servers.errors import StateError
from provisioners.providers.state import JsonStateStore

STATE_FILE = "servers-state.json"
FORMAT_VERSION = 1

STATUS_PREPARING = "preparing"
STATUS_READY = "ready"
STATUS_FAILED = "failed"


@dataclass(frozen=True)
class ProcessRef:
    """A process, told apart from a later one reusing its PID by its start time."""

    pid: int
    start_ticks: int

    @classmethod
    def current(cls) -> ProcessRef:
        """Return this process."""
        ticks = process_start_ticks(os.getpid())
        if ticks is None:
            raise StateError("cannot read this process's start time from /proc")
        return cls(os.getpid(), ticks)

    def alive(self) -> bool:
        """Return whether this very process still runs."""
        return process_start_ticks(self.pid) == self.start_ticks


@dataclass
class NetworkClaim:
    """A pre-made LAN in use under a network name (a constellation's)."""

    name: str
    lan: str
    cidr: str
    created_at: float


@dataclass
class ServerClaim:
    """A claimed server: which node it is and how far its preparation got."""

    server: str
    node: str
    network: str
    private_ip: str
    public_ip: str | None
    public_key: str
    tags: dict[str, str]
    size: str
    status: str
    created_at: float
    creator: ProcessRef
    error: str | None = None


@dataclass
class PendingCleanup:
    """A released server that could not be cleaned: done before anyone claims it again."""

    server: str
    public_keys: list[str]
    warning: str
    since: float


@dataclass
class ServersState:
    """Everything the provider remembers between runs."""

    networks: dict[str, NetworkClaim] = field(default_factory=dict)
    claims: dict[str, ServerClaim] = field(default_factory=dict)  # by server name
    pending_cleanups: dict[str, PendingCleanup] = field(default_factory=dict)
    host_keys: dict[str, str] = field(default_factory=dict)  # server name -> "type base64"

    def claim_of_node(self, node_name: str) -> ServerClaim | None:
        """Return the claim made for a node name, None when there is none."""
        return next((c for c in self.claims.values() if c.node == node_name), None)

    def to_json(self) -> dict[str, Any]:
        """Return the state as plain JSON data."""
        return {"version": FORMAT_VERSION, **asdict(self)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ServersState:
        """Build the state from data written by to_json."""
        if data.get("version") != FORMAT_VERSION:
            raise StateError(f"state format {data.get('version')!r} is not {FORMAT_VERSION}")
        return cls(
            networks={k: NetworkClaim(**v) for k, v in data["networks"].items()},
            claims={
                k: ServerClaim(**{**v, "creator": ProcessRef(**v["creator"])})
                for k, v in data["claims"].items()
            },
            pending_cleanups={k: PendingCleanup(**v) for k, v in data["pending_cleanups"].items()},
            host_keys=dict(data["host_keys"]),
        )


class StateFile:
    """The state document; changes happen inside transaction(), under a lock processes share."""

    def __init__(self, state_dir: Path) -> None:
        self.state_dir = state_dir
        self.path = state_dir / STATE_FILE
        self._json = JsonStateStore(state_dir, StateError)

    def read(self) -> ServersState:
        """Return the current state (a consistent snapshot: writes replace the file whole)."""
        data = self._json.read(STATE_FILE)
        if data is None:
            return ServersState()
        try:
            return ServersState.from_json(data)
        except (ValueError, KeyError, TypeError) as error:
            raise StateError(f"state file {self.path} is damaged: {error}") from error

    @contextmanager
    def transaction(self) -> Iterator[ServersState]:
        """Hold the lock, yield the state, write it back unless the block raised."""
        with self._json.lock():
            state = self.read()
            yield state
            self._json.write(STATE_FILE, state.to_json())


def process_start_ticks(pid: int) -> int | None:
    """Return a process's start time in clock ticks since boot, None when it does not exist."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    # The command name (field 2) may hold spaces and parentheses: split after its last ")".
    fields = stat.rsplit(")", 1)[1].split()
    return int(fields[19])  # field 22 of the whole line
