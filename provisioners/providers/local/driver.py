"""LocalNodeDriver: libcloud's NodeDriver API over hosts made of namespaces on this machine."""

import datetime
import functools
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Concatenate, ParamSpec, TypeVar

from libcloud.compute.base import (
    Node,
    NodeAuthPassword,
    NodeAuthSSHKey,
    NodeImage,
    NodeLocation,
    NodeSize,
)

from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.capacity import Capacity, Demand
from provisioners.providers.local import host, layers, netns
from provisioners.providers.local.addresses import (
    check_name,
    check_prefix,
    count_free_subnets,
    parse_address,
    parse_subnet,
)
from provisioners.providers.local.capacity import Budget, capacity, raise_limits
from provisioners.providers.local.errors import (
    InvalidRequestError,
    LocalProviderError,
    NetworkNotFoundError,
    NotRootError,
)
from provisioners.providers.local.network import LocalNetwork, NetworkManager
from provisioners.providers.local.nodes import NodeManager, NodeRequest, node_state
from provisioners.providers.local.state import NetworkRecord, NodeRecord, StateStore
from provisioners.providers.local.sweep import sweep_prefix
from provisioners.remote.ssh import Route

SIZE_ID = "host"
IMAGE_ID = "debian-12"
IMAGE_NAME = "debian-12 (this machine's root)"
LOCATION_ID = "localhost"
DEFAULT_BOOT_TIMEOUT_SECONDS = 60.0
SUBNET_PREFIX = 24  # what ex_create_network allocates
ROLE_TAG = "cloudsim:role"  # the tag naming a host's role: what its memory counts as

_Driver = TypeVar("_Driver", bound="LocalNodeDriver")
_Params = ParamSpec("_Params")
_Result = TypeVar("_Result")


def check_root() -> None:
    """Raise NotRootError unless this process runs as root."""
    uid = os.geteuid()
    if uid != 0:
        raise NotRootError(f"the local provider needs root (running as uid {uid})")


def requires_root(
    method: Callable[Concatenate[_Driver, _Params], _Result],
) -> Callable[Concatenate[_Driver, _Params], _Result]:
    """Make a driver method refuse to run unless the process is root."""

    @functools.wraps(method)
    def checked(self: _Driver, *args: _Params.args, **kwargs: _Params.kwargs) -> _Result:
        check_root()
        return method(self, *args, **kwargs)

    return checked


class LocalNodeDriver(CloudSimNodeDriver):
    """Hosts on this machine: each a network namespace, an overlay root, a PID namespace, sshd."""

    error_class = LocalProviderError

    type = "local"
    name = "CloudSim local hosts"

    def __init__(
        self,
        key: str = "local",
        secret: str | None = None,
        *,
        state_dir: str,
        subnet_pool: str = "10.211.0.0/16",
        public_cidr: str = "198.18.0.0/24",
        prefix: str = "cs",
        boot_timeout: float = DEFAULT_BOOT_TIMEOUT_SECONDS,
        hidden_paths: Sequence[str] = (),
        max_hosts: int = 0,
        host_memory_mib: int = Budget.host_memory_mib,
        memory_reserve_mib: int = Budget.memory_reserve_mib,
    ) -> None:
        super().__init__(key=key, secret=secret)
        if min(max_hosts, host_memory_mib, memory_reserve_mib) < 0:
            raise InvalidRequestError("max_hosts and memory figures must not be negative")
        self.budget = Budget(max_hosts, host_memory_mib, memory_reserve_mib)
        state_path = Path(state_dir)
        # Overlay mount options are separated by commas and colons.
        if not state_path.is_absolute() or any(char in state_dir for char in ",:"):
            raise InvalidRequestError(
                f"state_dir must be an absolute path without , or : ({state_dir!r})"
            )
        self.prefix = check_prefix(prefix)
        self.boot_timeout = boot_timeout
        self._store = StateStore(state_path, self.prefix)
        self._networks = NetworkManager(
            self._store,
            subnet_pool=parse_subnet(subnet_pool, max_prefixlen=24),
            public_subnet=parse_subnet(public_cidr),
        )
        # Hosts see this machine's "/" as their lower layer: keep the controller's secrets
        # (state_dir, whatever the caller names, e.g. the app's instance folder) out of sight.
        hidden = [*host.DEFAULT_HIDDEN_PATHS, state_dir, *hidden_paths]
        self._nodes = NodeManager(
            self._store,
            self._networks,
            boot_timeout=boot_timeout,
            hidden_paths=tuple(dict.fromkeys(Path(path).resolve() for path in hidden)),
        )

    @property
    def hosts_dir(self) -> Path:
        """Return where the hosts' overlay upper dirs live (a tmpfs while any host exists)."""
        return self._store.hosts_dir

    # -- networks ------------------------------------------------------------------------------

    @requires_root
    def ex_create_network(
        self, name: str, cidr: str | None = None, ex_gateway: str | None = None
    ) -> LocalNetwork:
        """Create a private network (a bridge in its own switch namespace) with a free subnet."""
        return self._to_network(self._networks.create(name, cidr, ex_gateway))

    @requires_root
    def ex_list_networks(self) -> list[LocalNetwork]:
        """Return this prefix's private networks."""
        return [self._to_network(record) for record in self._networks.list_private()]

    @requires_root
    def ex_get_network(self, name: str) -> LocalNetwork:
        """Return the named private network or raise NetworkNotFoundError."""
        return self._to_network(self._networks.get(name))

    @requires_root
    def ex_destroy_network(self, network: LocalNetwork) -> bool:
        """Destroy a network that no node uses any more; True also when it was already gone."""
        self._networks.destroy(network.name)
        return True

    @requires_root
    def ex_public_proxy_command(self, ip: str, port: int) -> list[str]:
        """Return an argv connecting stdio to ip:port from "the internet" (the public network)."""
        if not netns.namespace_exists(self._networks.public_switch_netns):
            raise NetworkNotFoundError(
                "there is no public network: no node of this prefix has ex_public=True"
            )
        return netns.connect_command(
            self._networks.public_switch_netns, str(parse_address(ip)), port
        )

    @requires_root
    def ex_public_command(self, argv: list[str]) -> list[str]:
        """Return argv wrapped to run on "the internet" (in the public network's namespace)."""
        if not netns.namespace_exists(self._networks.public_switch_netns):
            raise NetworkNotFoundError(
                "there is no public network: no node of this prefix has ex_public=True"
            )
        return ["nsenter", f"--net={netns.netns_path(self._networks.public_switch_netns)}", *argv]

    # -- capacity ------------------------------------------------------------------------------

    @requires_root
    def ex_prepare(self) -> list[str]:
        """Raise the kernel limits the hosts share to what this machine can hold; return changes.

        Idempotent (create_node calls it too): a limit already high enough is left alone.
        """
        return raise_limits(self.budget)

    def ex_capacity(self, pending: Demand | None = None) -> Capacity | None:
        """Return how many more hosts, networks and public addresses this machine can take,
        beyond the existing ones and what pending (launches not created yet) will use.

        None without root: no host can be made then, and the launch job says why.
        """
        if os.geteuid() != 0:
            return None
        nodes = self._store.read_nodes()
        public = self._networks.public_subnet
        # the network and broadcast addresses, and the "internet" end of the public network
        free_public = public.num_addresses - 3 - sum(1 for n in nodes if n.public_ip)
        roles = [node.tags.get(ROLE_TAG, "") for node in nodes]
        return capacity(self.budget, roles, self._free_subnets(), free_public, pending or Demand())

    def _free_subnets(self) -> int:
        taken = [
            parse_subnet(record.cidr)
            for record in self._store.read_all_prefixes_networks()
            if not record.public
        ]
        taken.append(self._networks.public_subnet)
        return count_free_subnets(self._networks.subnet_pool, SUBNET_PREFIX, taken)

    @requires_root
    def ex_image_layer(self, name: str, command: str) -> bool | None:
        """Make an image layer once: what command (bash, as root) changes in a scratch copy of
        this machine's root. Hosts created afterwards see it read-only, shared; True if made
        now, False if it existed."""
        check_name("layer", name)
        with self._store.lock():
            host.mount_hosts_tmpfs(self._store.hosts_dir, f"{self.prefix}-hosts")
            return layers.build_layer(self._store.hosts_dir, name, command)

    # -- nodes ---------------------------------------------------------------------------------

    @requires_root
    def list_nodes(self) -> list[Node]:
        """Return every node of this prefix, rediscovered from state_dir."""
        return [self._to_node(record) for record in self._store.read_nodes()]

    @requires_root
    def create_node(
        self,
        name: str,
        size: NodeSize | None = None,
        image: NodeImage | None = None,
        location: NodeLocation | None = None,
        auth: NodeAuthSSHKey | NodeAuthPassword | None = None,
        ex_network: LocalNetwork | None = None,
        ex_private_ip: str | None = None,
        ex_public: bool = False,
        ex_tags: dict[str, str] | None = None,
        ex_init: str | None = None,
    ) -> Node:
        """Create and boot a host; return once its sshd accepts connections."""
        check_name("node", name)
        self.ex_prepare()
        public_key = _public_key(auth)
        init = _choose_init(ex_init)
        tags = _check_tags(ex_tags)
        if ex_network is None:
            raise InvalidRequestError("create_node needs ex_network (from ex_create_network)")
        request = NodeRequest(
            name=name,
            network=ex_network.name,
            init=init,
            public_key=public_key,
            private_ip=ex_private_ip,
            public=ex_public,
            tags=tags,
            size=size.id if size is not None else SIZE_ID,
            image=image.id if image is not None else IMAGE_ID,
        )
        record = self._nodes.create(request)
        return self._to_node(record)

    @requires_root
    def destroy_node(self, node: Node) -> bool:
        """Remove every namespace, mount, process and file of the node; True if already gone."""
        record = self._nodes.find(node.name, node.id)
        if record is not None:
            self._nodes.destroy(record)
        return True

    @requires_root
    def reboot_node(self, node: Node) -> bool:
        """Restart the host's init, keeping its filesystem, host keys and addresses."""
        record = self._nodes.find(node.name, node.id)
        if record is None:
            raise LocalProviderError(f"no node {node.name!r} under prefix {self.prefix!r}")
        self._nodes.reboot(record)
        return True

    def ex_ssh_route(self, node: Node) -> Route:
        """Return the way into the node's namespace, to sshd on its loopback."""
        return Route(host=node.private_ips[0], proxy_command=tuple(node.extra["ssh_proxy_command"]))

    @requires_root
    def ex_sweep(self) -> list[str]:
        """Destroy every node and network of this prefix, then what is left without a record.

        Returns what the second step found (namespaces, cgroups, mounts whose records were
        lost, e.g. with a deleted state_dir): an empty list means nothing had leaked.
        """
        for node in self.list_nodes():
            self.destroy_node(node)
        for network in self.ex_list_networks():
            self.ex_destroy_network(network)
        with self._store.lock():
            if not self._store.read_nodes() and layers.only_layers(self._store.hosts_dir):
                host.unmount_hosts_tmpfs(self._store.hosts_dir)  # made before any host was
        leaked = sweep_prefix(self.prefix)
        with self._store.lock():
            self._store.remove_empty_dirs()
        return leaked

    @requires_root
    def list_sizes(self, location: NodeLocation | None = None) -> list[NodeSize]:
        """Return the single size: a host sharing this machine's CPUs and memory."""
        return [self._host_size()]

    @requires_root
    def list_images(self, location: NodeLocation | None = None) -> list[NodeImage]:
        """Return the single image: this machine's own root filesystem, seen through an overlay."""
        return [NodeImage(id=IMAGE_ID, name=IMAGE_NAME, driver=self, extra={"lowerdir": "/"})]

    @requires_root
    def list_locations(self) -> list[NodeLocation]:
        """Return the single location: this machine."""
        return [NodeLocation(id=LOCATION_ID, name=LOCATION_ID, country="", driver=self)]

    # -- internals -----------------------------------------------------------------------------

    def _host_size(self) -> NodeSize:
        memory_mib = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2**20
        return NodeSize(
            id=SIZE_ID,
            name=SIZE_ID,
            ram=memory_mib,
            disk=memory_mib // 2 // 1024,  # the hosts' tmpfs may grow to half the RAM
            bandwidth=None,
            price=0.0,
            driver=self,
            extra={"cpus": os.cpu_count()},
        )

    def _to_network(self, record: NetworkRecord) -> LocalNetwork:
        return LocalNetwork(
            id=record.name,
            name=record.name,
            cidr=record.cidr,
            gateway=record.gateway,
            driver=self,
            extra={"switch_netns": record.switch_netns, "created_at": record.created_at},
        )

    def _to_node(self, record: NodeRecord) -> Node:
        init_pid = record.init_process.pid if record.init_process else None
        return Node(
            id=record.id,
            name=record.name,
            state=node_state(record),
            public_ips=[record.public_ip] if record.public_ip else [],
            private_ips=[record.private_ip],
            driver=self,
            size=self._host_size(),
            image=NodeImage(record.image, IMAGE_NAME, driver=self),
            created_at=datetime.datetime.fromtimestamp(record.created_at, tz=datetime.UTC),
            extra={
                "netns": record.netns,
                "network": record.network,
                "tags": dict(record.tags),
                "init": record.init,
                "pid": init_pid,
                "launcher_pid": record.launcher.pid if record.launcher else None,
                "machine": record.machine,
                "ssh_proxy_command": netns.connect_command(
                    record.netns, "127.0.0.1", host.SSH_PORT
                ),
            },
        )


def _public_key(auth: Any) -> str:
    if not isinstance(auth, NodeAuthSSHKey):
        raise InvalidRequestError("create_node needs auth=NodeAuthSSHKey(public_key)")
    public_key = str(auth.pubkey).strip()
    if (
        not public_key
        or "\n" in public_key
        or not public_key.split()[0].startswith(("ssh-", "ecdsa-", "sk-"))
    ):
        raise InvalidRequestError("auth must hold one OpenSSH public key line")
    return public_key


def _choose_init(requested: str | None) -> str:
    if requested is None:
        return host.INIT_SYSTEMD if host.systemd_boot_available() else host.INIT_MINIMAL
    if requested not in host.INIT_MODES:
        raise InvalidRequestError(f"ex_init must be one of {host.INIT_MODES} or None")
    if requested == host.INIT_SYSTEMD and not host.systemd_boot_available():
        raise InvalidRequestError("ex_init='systemd' needs systemd-nspawn (systemd-container)")
    return requested


def _check_tags(tags: dict[str, str] | None) -> dict[str, str]:
    checked = dict(tags or {})
    for key, value in checked.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InvalidRequestError(f"ex_tags must map str to str (got {key!r}: {value!r})")
    return checked
