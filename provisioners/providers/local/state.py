"""Records of networks and nodes, kept in the providers' JSON state store under state_dir."""

from collections.abc import Iterator
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from provisioners.providers.local.errors import LocalProviderError
from provisioners.providers.local.processes import ProcessId
from provisioners.providers.state import JsonStateStore

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
        self._json = JsonStateStore(state_dir, LocalProviderError)

    def lock(self) -> AbstractContextManager[None]:
        """Hold the state_dir-wide lock (between threads and processes alike)."""
        return self._json.lock()

    def node_dir(self, name: str) -> Path:
        """Return the directory holding a node's record, boot log and authorized key."""
        return self.nodes_dir / name

    def host_dir(self, name: str) -> Path:
        """Return the tmpfs directory holding a node's overlay upper/work/root."""
        return self.hosts_dir / name

    def read_networks(self) -> list[NetworkRecord]:
        """Return this prefix's network records."""
        return list(self._networks(f"{self.prefix}/networks/*.json"))

    def read_all_prefixes_networks(self) -> list[NetworkRecord]:
        """Return the network records of every prefix sharing state_dir."""
        return list(self._networks("*/networks/*.json"))

    def find_network(self, name: str) -> NetworkRecord | None:
        """Return the named network's record, None when absent."""
        data = self._json.read(f"{self.prefix}/networks/{name}.json")
        return None if data is None else NetworkRecord(**data)

    def write_network(self, record: NetworkRecord) -> None:
        """Persist a network record."""
        self._json.write(f"{self.prefix}/networks/{record.name}.json", asdict(record))

    def delete_network(self, name: str) -> None:
        """Forget a network record; no-op when absent."""
        self._json.delete(f"{self.prefix}/networks/{name}.json")

    def read_nodes(self) -> list[NodeRecord]:
        """Return this prefix's node records."""
        records = (
            self._json.read(n) for n in self._json.names(f"{self.prefix}/nodes/*/record.json")
        )
        return [NodeRecord.from_json(data) for data in records if data is not None]

    def find_node(self, name: str) -> NodeRecord | None:
        """Return the named node's record, None when absent."""
        data = self._json.read(f"{self.prefix}/nodes/{name}/record.json")
        return None if data is None else NodeRecord.from_json(data)

    def write_node(self, record: NodeRecord) -> None:
        """Persist a node record, creating its directory."""
        self._json.write(f"{self.prefix}/nodes/{record.name}/record.json", record.to_json())

    def delete_node(self, name: str) -> None:
        """Remove a node's directory (record, log, key); no-op when absent."""
        self._json.delete(f"{self.prefix}/nodes/{name}")

    def remove_empty_dirs(self) -> None:
        """Remove this prefix's directories once they hold nothing."""
        for directory in (self.networks_dir, self.nodes_dir, self.hosts_dir, self.root):
            # The hosts dir stays while its tmpfs is mounted, empty or not.
            if directory.is_dir() and not directory.is_mount() and not any(directory.iterdir()):
                directory.rmdir()

    def _networks(self, pattern: str) -> Iterator[NetworkRecord]:
        for name in self._json.names(pattern):
            data = self._json.read(name)
            if data is not None:
                yield NetworkRecord(**data)
