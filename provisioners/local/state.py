"""Persisted JSON records of networks and nodes under state_dir, guarded by one file lock."""

import fcntl
import json
import os
import shutil
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from provisioners.local.errors import LocalProviderError
from provisioners.local.processes import ProcessId

STATUS_CREATING = "creating"
STATUS_RUNNING = "running"


@dataclass
class NetworkRecord:
    """What the provider knows about one network (a bridge in a switch namespace)."""

    name: str
    cidr: str
    switch_netns: str
    gateway: str | None = None
    public: bool = False
    created_at: float = 0.0


@dataclass
class NodeRecord:
    """What the provider knows about one host, enough to rediscover or destroy it."""

    id: str
    name: str
    network: str
    netns: str
    machine: str
    init: str
    private_ip: str
    public_ip: str | None = None
    machine_id: str = ""
    cgroups: list[str] = field(default_factory=list)
    tags: dict[str, str] = field(default_factory=dict)
    size: str = ""
    image: str = ""
    status: str = STATUS_CREATING
    created_at: float = 0.0
    creator: ProcessId | None = None
    launcher: ProcessId | None = None
    init_process: ProcessId | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the record as plain JSON data."""
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "NodeRecord":
        """Build a record from JSON data written by to_json."""
        processes = {
            key: ProcessId(**data[key]) if data.get(key) else None
            for key in ("creator", "launcher", "init_process")
        }
        return cls(**{**data, **processes})


class StateStore:
    """Records of one prefix under state_dir; the lock is shared by every prefix."""

    def __init__(self, state_dir: Path, prefix: str) -> None:
        self.state_dir = state_dir
        self.prefix = prefix
        self.root = state_dir / prefix
        self.networks_dir = self.root / "networks"
        self.nodes_dir = self.root / "nodes"
        self.hosts_dir = self.root / "hosts"

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the state_dir-wide lock (between threads and processes alike)."""
        self.state_dir.mkdir(parents=True, exist_ok=True)
        # A fresh open file description per holder: flock then excludes threads too.
        with open(self.state_dir / ".lock", "a") as lock_file:
            fcntl.flock(lock_file, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(lock_file, fcntl.LOCK_UN)

    def node_dir(self, name: str) -> Path:
        """Return the directory holding a node's record, boot log and authorized key."""
        return self.nodes_dir / name

    def host_dir(self, name: str) -> Path:
        """Return the tmpfs directory holding a node's overlay upper/work/root."""
        return self.hosts_dir / name

    def read_networks(self) -> list[NetworkRecord]:
        """Return this prefix's network records."""
        return _read_networks(_json_files(self.networks_dir))

    def read_all_prefixes_networks(self) -> list[NetworkRecord]:
        """Return the network records of every prefix sharing state_dir."""
        if not self.state_dir.is_dir():
            return []
        return _read_networks(
            [path for d in sorted(self.state_dir.iterdir()) for path in _json_files(d / "networks")]
        )

    def find_network(self, name: str) -> NetworkRecord | None:
        """Return the named network's record, None when absent."""
        data = _read_json(self.networks_dir / f"{name}.json")
        return None if data is None else NetworkRecord(**data)

    def write_network(self, record: NetworkRecord) -> None:
        """Persist a network record."""
        _write_json(self.networks_dir / f"{record.name}.json", asdict(record))

    def delete_network(self, name: str) -> None:
        """Forget a network record; no-op when absent."""
        (self.networks_dir / f"{name}.json").unlink(missing_ok=True)

    def read_nodes(self) -> list[NodeRecord]:
        """Return this prefix's node records."""
        if not self.nodes_dir.is_dir():
            return []
        records = []
        for path in sorted(self.nodes_dir.glob("*/record.json")):
            data = _read_json(path)
            if data is not None:
                records.append(NodeRecord.from_json(data))
        return records

    def find_node(self, name: str) -> NodeRecord | None:
        """Return the named node's record, None when absent."""
        data = _read_json(self.node_dir(name) / "record.json")
        return None if data is None else NodeRecord.from_json(data)

    def write_node(self, record: NodeRecord) -> None:
        """Persist a node record, creating its directory."""
        _write_json(self.node_dir(record.name) / "record.json", record.to_json())

    def delete_node(self, name: str) -> None:
        """Remove a node's directory (record, log, key); no-op when absent."""
        try:
            shutil.rmtree(self.node_dir(name))
        except FileNotFoundError:
            return

    def remove_empty_dirs(self) -> None:
        """Remove this prefix's directories once they hold nothing."""
        for directory in (self.networks_dir, self.nodes_dir, self.hosts_dir, self.root):
            # The hosts dir stays while its tmpfs is mounted, empty or not.
            if directory.is_dir() and not directory.is_mount() and not any(directory.iterdir()):
                directory.rmdir()


def _json_files(directory: Path) -> list[Path]:
    return sorted(directory.glob("*.json")) if directory.is_dir() else []


def _read_networks(paths: list[Path]) -> list[NetworkRecord]:
    records = []
    for path in paths:
        data = _read_json(path)
        if data is not None:
            records.append(NetworkRecord(**data))
    return records


def _read_json(path: Path) -> dict[str, Any] | None:
    """Return a record's data, None when it does not exist (or was just deleted)."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as error:
        raise LocalProviderError(f"cannot read state record {path}: {error}") from error
    if not isinstance(data, dict):
        raise LocalProviderError(f"state record {path} is not a JSON object")
    return data


def _write_json(path: Path, data: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    # One temporary file per writer: threads and processes may write the same record.
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    temporary.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    # Readers never see half a record: replace is atomic within one filesystem.
    os.replace(temporary, path)
