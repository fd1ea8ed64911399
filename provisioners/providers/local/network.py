"""Private networks and the shared public network: bridges inside their own switch namespaces."""

import time
from ipaddress import IPv4Network

from provisioners.providers.base import ProviderNetwork
from provisioners.providers.local import netns
from provisioners.providers.local.addresses import (
    allocate_subnet,
    check_name,
    check_subnet_free,
    gateway_address,
    interface_cidr,
    parse_address,
    parse_subnet,
)
from provisioners.providers.local.errors import (
    AddressError,
    InvalidRequestError,
    LocalProviderError,
    NameInUseError,
    NetworkInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.local.state import NetworkRecord, StateStore

PUBLIC_NETWORK_NAME = "public"


class LocalNetwork(ProviderNetwork):
    """A private network of the local provider, as handed to create_node(ex_network=...)."""


class NetworkManager:
    """Create, find and destroy network records and the switch namespaces behind them."""

    def __init__(
        self, store: StateStore, *, subnet_pool: IPv4Network, public_subnet: IPv4Network
    ) -> None:
        self._store = store
        self.subnet_pool = subnet_pool
        self.public_subnet = public_subnet
        self.public_switch_netns = f"{store.prefix}-s-{PUBLIC_NETWORK_NAME}"

    def create(self, name: str, cidr: str | None, gateway: str | None) -> NetworkRecord:
        """Allocate (or check) a subnet, persist the record and build the switch namespace."""
        check_name("network", name)
        if name == PUBLIC_NETWORK_NAME:
            raise InvalidRequestError(f"{PUBLIC_NETWORK_NAME!r} is reserved for the public network")
        with self._store.lock():
            if self._store.find_network(name) is not None:
                raise NameInUseError(f"a network named {name!r} already exists")
            taken = [
                parse_subnet(record.cidr)
                for record in self._store.read_all_prefixes_networks()
                if not record.public
            ]
            taken.append(self.public_subnet)
            if cidr is None:
                subnet = allocate_subnet(self.subnet_pool, taken)
            else:
                subnet = parse_subnet(cidr)
                check_subnet_free(subnet, taken)
            if gateway is not None:
                gateway_ip = parse_address(gateway)
                if gateway_ip not in set(subnet.hosts()):
                    raise AddressError(f"gateway {gateway} is not a host address of {subnet}")
            record = NetworkRecord(
                name=name,
                cidr=str(subnet),
                switch_netns=f"{self._store.prefix}-s-{name}",
                gateway=gateway,
                created_at=time.time(),
            )
            self._build(record, bridge_address=None)
        return record

    def ensure_public(self) -> NetworkRecord:
        """Return the public network, creating it first if needed (caller holds the lock)."""
        record = self._store.find_network(PUBLIC_NETWORK_NAME)
        if record is not None:
            return record
        internet = gateway_address(self.public_subnet)
        record = NetworkRecord(
            name=PUBLIC_NETWORK_NAME,
            cidr=str(self.public_subnet),
            switch_netns=self.public_switch_netns,
            gateway=str(internet),
            public=True,
            created_at=time.time(),
        )
        # The bridge's own address plays "the internet": routers reach it, it reaches them.
        self._build(record, bridge_address=interface_cidr(internet, self.public_subnet))
        return record

    def public_record(self) -> NetworkRecord:
        """Return the public network's record, which ensure_public created."""
        record = self._store.find_network(PUBLIC_NETWORK_NAME)
        if record is None:
            raise NetworkNotFoundError("the public network does not exist")
        return record

    def destroy_public(self) -> None:
        """Remove the public network once no node uses it (caller holds the lock)."""
        netns.delete_namespace(self.public_switch_netns)
        self._store.delete_network(PUBLIC_NETWORK_NAME)

    def get(self, name: str) -> NetworkRecord:
        """Return a private network's record or raise NetworkNotFoundError."""
        record = self._store.find_network(name)
        if record is None or record.public:
            raise NetworkNotFoundError(
                f"no network named {name!r} under prefix {self._store.prefix!r}"
            )
        return record

    def list_private(self) -> list[NetworkRecord]:
        """Return this prefix's private network records."""
        return [record for record in self._store.read_networks() if not record.public]

    def destroy(self, name: str) -> None:
        """Delete a private network unless nodes are still attached; no-op when already gone."""
        with self._store.lock():
            record = self._store.find_network(name)
            if record is None or record.public:
                return
            attached = sorted(n.name for n in self._store.read_nodes() if n.network == name)
            if attached:
                raise NetworkInUseError(
                    f"network {name!r} still has nodes attached ({', '.join(attached)}): "
                    "destroy them first"
                )
            netns.delete_namespace(record.switch_netns)
            self._store.delete_network(name)
            self._store.remove_empty_dirs()

    def _build(self, record: NetworkRecord, bridge_address: str | None) -> None:
        """Persist the record, then create its switch namespace; undo both on failure."""
        self._store.write_network(record)
        try:
            netns.create_namespace(record.switch_netns)
            netns.create_bridge(record.switch_netns, bridge_address)
        except LocalProviderError as error:
            try:
                netns.delete_namespace(record.switch_netns)
            except LocalProviderError as cleanup_error:
                error.add_note(f"removing {record.switch_netns} failed too: {cleanup_error}")
            self._store.delete_network(record.name)
            raise
