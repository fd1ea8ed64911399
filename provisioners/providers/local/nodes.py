"""Node lifecycle: reserve addresses, wire namespaces, boot, tear down, judge liveness."""

import os
import secrets
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from libcloud.compute.types import NodeState

from provisioners.providers.local import host, netns, processes
from provisioners.providers.local.addresses import (
    allocate_address,
    check_address_free,
    parse_address,
    parse_subnet,
)
from provisioners.providers.local.cgroups import host_cgroup_dirs, remove_cgroup_dirs
from provisioners.providers.local.errors import HostBootError, LocalProviderError, NameInUseError
from provisioners.providers.local.network import NetworkManager
from provisioners.providers.local.state import (
    STATUS_CREATING,
    STATUS_RUNNING,
    NodeRecord,
    StateStore,
)

LAN_INTERFACE = "eth0"
PUBLIC_INTERFACE = "eth1"


@dataclass(frozen=True)
class NodeRequest:
    """What create_node asked for, already validated."""

    name: str
    network: str
    init: str
    public_key: str
    private_ip: str | None
    public: bool
    tags: dict[str, str]
    size: str
    image: str


class NodeManager:
    """Create, reboot and destroy hosts, keeping their records in the state store."""

    def __init__(
        self,
        store: StateStore,
        networks: NetworkManager,
        *,
        boot_timeout: float,
        hidden_paths: tuple[Path, ...],
    ) -> None:
        self._store = store
        self._networks = networks
        self._boot_timeout = boot_timeout
        self._hidden_paths = hidden_paths

    def create(self, request: NodeRequest) -> NodeRecord:
        """Reserve, wire and boot a host; on any failure remove everything it made."""
        record = self._reserve(request)
        spec = self.host_spec(record)
        try:
            spec.authorized_keys.write_text(request.public_key + "\n")
            self._plug(record)
            self._boot(record, spec)
        except BaseException as error:
            log_tail = host.boot_log_tail(spec)
            if record.init == host.INIT_SYSTEMD:
                journal = host.systemd_journal_tail(record.init_process)
                log_tail = f"{log_tail}\n--- journal of {record.name} ---\n{journal}"
            try:
                self.destroy(record)
            except LocalProviderError as cleanup_error:
                error.add_note(f"cleaning up node {record.name} failed too: {cleanup_error}")
            if isinstance(error, LocalProviderError):
                raise HostBootError(
                    f"creating node {record.name} failed: {error}\n"
                    f"--- boot log of {record.name} (last lines) ---\n{log_tail}"
                ) from error
            raise
        return record

    def reboot(self, record: NodeRecord) -> None:
        """Restart the host's init on its existing filesystem and network namespace."""
        host.stop_host(record.launcher, record.init_process)
        remove_cgroup_dirs(self.host_spec(record).cgroup_dirs, host.KILL_WAIT_SECONDS)
        record.launcher = record.init_process = None
        record.status = STATUS_CREATING
        record.creator = processes.identify(os.getpid())
        spec = self.host_spec(record)
        spec.launcher_pidfile.unlink(missing_ok=True)
        self._boot(record, spec)

    def destroy(self, record: NodeRecord) -> None:
        """Stop the host's processes, delete its namespace and files, forget it."""
        spec = self.host_spec(record)
        launcher = record.launcher or _launcher_from_pidfile(spec)
        host.stop_host(launcher, record.init_process)
        remove_cgroup_dirs(spec.cgroup_dirs, host.KILL_WAIT_SECONDS)
        for pid in netns.namespace_pids(record.netns):
            # Stragglers joined the namespace from outside (nsenter); the namespace is ours.
            straggler = processes.identify(pid)
            if straggler is not None:
                processes.kill(straggler, host.KILL_WAIT_SECONDS)
        netns.delete_namespace(record.netns)
        host.remove_host_files(spec)
        with self._store.lock():
            current = self._store.find_node(record.name)
            if current is not None and current.id == record.id:
                self._store.delete_node(record.name)
            remaining = self._store.read_nodes()
            if not any(node.public_ip for node in remaining):
                self._networks.destroy_public()
            if not remaining:
                host.unmount_hosts_tmpfs(self._store.hosts_dir)
            self._store.remove_empty_dirs()

    def find(self, name: str | None, node_id: str | None) -> NodeRecord | None:
        """Return the record with that name (and id, when given), None when it is gone."""
        record = self._store.find_node(name) if name else None
        if record is None and node_id:
            record = next((r for r in self._store.read_nodes() if r.id == node_id), None)
        if record is None or (node_id and record.id != node_id):
            return None
        return record

    def host_spec(self, record: NodeRecord) -> host.HostSpec:
        """Return the boot parameters of a recorded host."""
        return host.HostSpec(
            hostname=record.name,
            machine=record.machine,
            netns=record.netns,
            init=record.init,
            host_dir=self._store.host_dir(record.name),
            node_dir=self._store.node_dir(record.name),
            machine_id=record.machine_id,
            hidden_paths=self._hidden_paths,
            cgroup_dirs=tuple(Path(path) for path in record.cgroups),
        )

    def _reserve(self, request: NodeRequest) -> NodeRecord:
        """Allocate addresses and persist a "creating" record, all under the state lock."""
        prefix = self._store.prefix
        with self._store.lock():
            if self._store.find_node(request.name) is not None:
                raise NameInUseError(f"a node named {request.name!r} already exists")
            network = self._networks.get(request.network)
            nodes = self._store.read_nodes()
            subnet = parse_subnet(network.cidr)
            lan_taken = [parse_address(n.private_ip) for n in nodes if n.network == network.name]
            if request.private_ip is None:
                lan_address = allocate_address(subnet, lan_taken)
            else:
                lan_address = parse_address(request.private_ip)
                check_address_free(subnet, lan_address, lan_taken)
            public_address = None
            if request.public:
                public_taken = [parse_address(n.public_ip) for n in nodes if n.public_ip]
                public_address = allocate_address(self._networks.public_subnet, public_taken)
                self._networks.ensure_public()
            host.mount_hosts_tmpfs(self._store.hosts_dir, f"{prefix}-hosts")
            record = NodeRecord(
                id=secrets.token_hex(6),
                name=request.name,
                network=network.name,
                netns=f"{prefix}-h-{request.name}",
                machine=f"{prefix}-{request.name}",
                init=request.init,
                private_ip=str(lan_address),
                public_ip=None if public_address is None else str(public_address),
                machine_id=uuid.uuid4().hex,
                cgroups=[str(path) for path in host_cgroup_dirs(f"{prefix}-{request.name}")],
                tags=dict(request.tags),
                size=request.size,
                image=request.image,
                created_at=time.time(),
                creator=processes.identify(os.getpid()),
            )
            self._store.write_node(record)
        return record

    def _plug(self, record: NodeRecord) -> None:
        """Create the node's network namespace and wire it to its switches."""
        network = self._networks.get(record.network)
        port = f"p{record.id}"
        netns.create_namespace(record.netns)
        netns.plug_into_switch(
            record.netns, LAN_INTERFACE, network.switch_netns, port,
            f"{record.private_ip}/{parse_subnet(network.cidr).prefixlen}",
        )  # fmt: skip
        if record.public_ip is not None:
            public = self._networks.public_record()
            netns.plug_into_switch(
                record.netns, PUBLIC_INTERFACE, public.switch_netns, port,
                f"{record.public_ip}/{self._networks.public_subnet.prefixlen}",
            )  # fmt: skip
            if public.gateway is not None:
                netns.add_default_route(record.netns, public.gateway)
        elif network.gateway is not None:
            netns.add_default_route(record.netns, network.gateway)

    def _boot(self, record: NodeRecord, spec: host.HostSpec) -> None:
        """Start the host, record its processes, wait for sshd, mark it running."""
        started = host.start_host(spec, self._boot_timeout)
        record.launcher, record.init_process = started.launcher, started.init
        self._store.write_node(record)
        host.wait_for_sshd(spec, started, self._boot_timeout)
        record.status = STATUS_RUNNING
        self._store.write_node(record)


def node_state(record: NodeRecord) -> NodeState:
    """Map a record and the liveness of its processes to libcloud's NodeState."""
    if record.status == STATUS_CREATING and not (
        record.creator is not None and processes.is_alive(record.creator)
    ):
        # The create_node (or reboot) that owned it died half-way: nobody will finish it.
        return NodeState.ERROR
    if record.init_process is not None and processes.is_alive(record.init_process):
        return NodeState.RUNNING if record.status == STATUS_RUNNING else NodeState.PENDING
    if record.status == STATUS_CREATING:
        return NodeState.PENDING
    return NodeState.STOPPED


def _launcher_from_pidfile(spec: host.HostSpec) -> processes.ProcessId | None:
    """Return the launcher a crashed create_node started but did not record, if still ours."""
    if not spec.launcher_pidfile.exists():
        return None
    text = spec.launcher_pidfile.read_text().strip()
    if not text.isdigit():
        return None
    candidate = processes.identify(int(text))
    if candidate is None:
        return None
    try:
        command_line = Path(f"/proc/{candidate.pid}/cmdline").read_bytes()
    except FileNotFoundError:
        return None
    # A recycled PID would not carry this host's directory on its command line.
    return candidate if str(spec.host_dir).encode() in command_line else None
