"""ServersNodeDriver: libcloud's NodeDriver API over machines that already exist (an inventory).

Creating a node claims a free server and prepares it over SSH with the inventory's login key
(hostname, the node's authorized key); destroying one cleans the server up and frees it.
"""

from __future__ import annotations

import ipaddress
import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from libcloud.compute.base import (
    Node,
    NodeAuthPassword,
    NodeAuthSSHKey,
    NodeImage,
    NodeLocation,
    NodeSize,
)

from provisioners.providers.base import BEHIND_PUBLIC_MACHINE, CloudSimNodeDriver
from provisioners.providers.servers import remote
from provisioners.providers.servers.claims import (
    check_network_name,
    check_node_name,
    check_tags,
    choose_server,
    free_lan,
)
from provisioners.providers.servers.errors import (
    InvalidRequestError,
    NetworkInUseError,
    NetworkNotFoundError,
    ServerCleanupError,
    ServerSetupError,
    ServersProviderError,
)
from provisioners.providers.servers.inventory import Inventory, Server
from provisioners.providers.servers.nodes import ServersNetwork, server_status, to_network, to_node
from provisioners.providers.servers.state import (
    STATUS_FAILED,
    STATUS_PREPARING,
    STATUS_READY,
    NetworkClaim,
    PendingCleanup,
    ProcessRef,
    ServerClaim,
    StateFile,
)
from provisioners.remote.ssh import (
    CommandFailed,
    ConnectPolicy,
    HostKeys,
    Route,
    SSHError,
    SSHExecutor,
    SSHTarget,
)

EXISTING = "existing"
LOCATION_ID = "servers"
DEFAULT_CONNECT_TIMEOUT_SECONDS = 60.0
# A probe that never connects: what "the internet" gets at a private address.
UNROUTABLE = ("false",)
log = logging.getLogger(__name__)


class ServersNodeDriver(CloudSimNodeDriver):
    """Existing servers reached over SSH: create claims and prepares one, destroy cleans it up."""

    error_class = ServersProviderError

    type = "servers"
    name = "CloudSim existing servers"

    def __init__(
        self,
        key: str = "servers",
        secret: str | None = None,
        *,
        inventory: Inventory | Sequence[Mapping[str, Any]],
        state_dir: str,
        connect_timeout: float = DEFAULT_CONNECT_TIMEOUT_SECONDS,
    ) -> None:
        super().__init__(key=key, secret=secret)
        if not Path(state_dir).is_absolute():
            raise InvalidRequestError(f"state_dir must be an absolute path ({state_dir!r})")
        self.inventory = Inventory.of(inventory)
        self.connect_timeout = connect_timeout
        self._state = StateFile(Path(state_dir))
        # pinned in the inventory, else trusted on first use and recorded in the state
        self._host_keys = HostKeys(lookup=self._known_host_key, record=self._record_host_key)

    # -- networks ------------------------------------------------------------------------------

    def ex_create_network(self, name: str, cidr: str | None = None) -> ServersNetwork:
        """Take a free pre-made network (on cidr, if given) for name; return the one name has."""
        check_network_name(name)
        if cidr is not None:
            try:
                cidr = str(ipaddress.IPv4Network(cidr))
            except ValueError as error:
                raise InvalidRequestError(f"cidr {cidr!r} is not an IPv4 network") from error
        with self._state.transaction() as state:
            existing = state.networks.get(name)
            if existing is not None:
                if cidr is not None and cidr != existing.cidr:
                    raise InvalidRequestError(
                        f"network {name!r} exists on {existing.cidr}, not {cidr}"
                    )
                return to_network(self, existing)
            lan, lan_cidr = free_lan(self.inventory, state, name, cidr)
            claim = NetworkClaim(name=name, lan=lan, cidr=lan_cidr, created_at=time.time())
            state.networks[name] = claim
            return to_network(self, claim)

    def ex_list_networks(self) -> list[ServersNetwork]:
        """Return the networks in use."""
        networks = self._state.read().networks.values()
        return [to_network(self, claim) for claim in sorted(networks, key=lambda n: n.name)]

    def ex_get_network(self, name: str) -> ServersNetwork:
        """Return the named network in use, or raise NetworkNotFoundError."""
        claim = self._state.read().networks.get(name)
        if claim is None:
            raise NetworkNotFoundError(f"no network {name!r} is in use")
        return to_network(self, claim)

    def ex_destroy_network(self, network: ServersNetwork | str) -> bool:
        """Free a network no node uses any more; True also when it was not in use."""
        name = network if isinstance(network, str) else network.name
        with self._state.transaction() as state:
            nodes = sorted(c.node for c in state.claims.values() if c.network == name)
            if nodes:
                raise NetworkInUseError(f"network {name!r} still has nodes: {', '.join(nodes)}")
            state.networks.pop(name, None)
        return True

    # -- nodes ---------------------------------------------------------------------------------

    def create_node(
        self,
        name: str,
        size: NodeSize | None = None,
        image: NodeImage | None = None,
        location: NodeLocation | None = None,
        auth: NodeAuthSSHKey | NodeAuthPassword | None = None,
        ex_network: ServersNetwork | str | None = None,
        ex_private_ip: str | None = None,
        ex_public: bool = False,
        ex_tags: dict[str, str] | None = None,
    ) -> Node:
        """Claim a free server of ex_network and prepare it; a name already claimed is returned.

        A size other than "existing" asks for a server with that capability (e.g. "gpu").
        """
        check_node_name(name)
        if not isinstance(auth, NodeAuthSSHKey):
            raise InvalidRequestError("create_node needs auth=NodeAuthSSHKey(public_key)")
        public_key = str(auth.pubkey).strip()
        remote.key_blob(public_key)
        tags = check_tags(ex_tags)
        if ex_network is None:
            raise InvalidRequestError("create_node needs ex_network (from ex_create_network)")
        network_name = ex_network if isinstance(ex_network, str) else ex_network.name
        capability = size.id if size is not None and size.id != EXISTING else None
        me = ProcessRef.current()
        with self._state.transaction() as state:
            network = state.networks.get(network_name)
            if network is None:
                raise NetworkNotFoundError(f"no network {network_name!r} is in use")
            claim = state.claim_of_node(name)
            stale_keys: list[str] = []
            if claim is not None:
                if claim.network != network_name:
                    raise InvalidRequestError(
                        f"node {name!r} exists in network {claim.network!r}, not {network_name!r}"
                    )
                if claim.status == STATUS_READY or (
                    claim.status == STATUS_PREPARING
                    and claim.creator.alive()
                    and claim.creator != me
                ):
                    return to_node(self, claim)
                # Preparation failed or its process died: prepare again, from this process.
                if claim.public_key != public_key:
                    stale_keys.append(claim.public_key)
                claim.status, claim.error, claim.creator = STATUS_PREPARING, None, me
                claim.public_key, claim.tags = public_key, tags
            else:
                server = choose_server(
                    self.inventory,
                    state,
                    network,
                    private_ip=ex_private_ip,
                    public=bool(ex_public),
                    capability=capability,
                )
                claim = ServerClaim(
                    server=server.name,
                    node=name,
                    network=network_name,
                    private_ip=server.private_ip,
                    public_ip=server.public_ip,
                    public_key=public_key,
                    tags=tags,
                    size=size.id if size is not None else EXISTING,
                    status=STATUS_PREPARING,
                    created_at=time.time(),
                    creator=me,
                )
                state.claims[server.name] = claim
            pending = state.pending_cleanups.get(claim.server)
        server = self._server(claim.server)
        try:
            with self._executor(server) as executor:
                if pending is not None:
                    log.info("server %s: cleaning up after an earlier node first", server.name)
                    remote.clean_up(executor, server, pending.public_keys)
                remote.prepare(executor, server, name, public_key, stale_keys)
        except SSHError as error:
            self._mark_failed(server.name, name, str(error))
            raise ServerSetupError(
                f"server {server.name} (claimed for node {name}) could not be prepared: {error}"
            ) from error
        with self._state.transaction() as state:
            current = state.claims.get(server.name)
            if current is None or current.node != name:
                raise ServersProviderError(f"node {name!r} was destroyed while being prepared")
            current.status = STATUS_READY
            state.pending_cleanups.pop(server.name, None)
            return to_node(self, current)

    def destroy_node(self, node: Node) -> bool:
        """Clean the node's server up and free it; True also when it is not claimed.

        A server that cannot be cleaned up (unreachable, a command failed) is freed all the
        same, so that terminating a constellation finishes, with a warning recorded in the
        state: its cleanup runs again before the server is next claimed, which fails while
        the server stays unreachable.
        """
        claim = self._state.read().claim_of_node(node.name)
        if claim is None or (node.id and str(node.id) != claim.server):
            return True
        pending = self._state.read().pending_cleanups.get(claim.server)
        keys = sorted({claim.public_key, *(pending.public_keys if pending else [])})
        warning = None
        server = self.inventory.server(claim.server)
        if server is None:
            warning = f"server {claim.server} is no longer in the inventory; not cleaned up"
        else:
            try:
                with self._executor(server) as executor:
                    remote.clean_up(executor, server, keys)
            except SSHError as error:
                warning = f"server {server.name} was released without cleanup: {error}"
        if warning is not None:
            log.warning("%s (node %s)", warning, node.name)
        with self._state.transaction() as state:
            current = state.claims.get(claim.server)
            if current is not None and current.node == node.name:
                del state.claims[claim.server]
            if warning is None:
                state.pending_cleanups.pop(claim.server, None)
            else:
                state.pending_cleanups[claim.server] = PendingCleanup(
                    server=claim.server, public_keys=keys, warning=warning, since=time.time()
                )
        return True

    def ex_destroy_node_through(self, node: Node, executor: SSHExecutor, target: SSHTarget) -> bool:
        """Clean the node's server through target (the route its launch used, e.g. through the
        router), else directly with the inventory's login; free the server only once clean.

        A server cleaned neither way stays claimed by the node and ServerCleanupError says
        why: the node is listed again, so a retry (through the same route) finds it.
        """
        claim = self._state.read().claim_of_node(node.name)
        if claim is None or (node.id and str(node.id) != claim.server):
            return True
        pending = self._state.read().pending_cleanups.get(claim.server)
        keys = sorted({claim.public_key, *(pending.public_keys if pending else [])})
        server = self.inventory.server(claim.server)
        if server is None:
            raise ServerCleanupError(
                f"server {claim.server} is no longer in the inventory: put it back to clean it"
            )
        try:
            remote.clean_up(executor, server, keys, via=target)
        except CommandFailed as error:
            # reached, and the cleanup itself failed: its own address would fail the same way
            raise ServerCleanupError(f"server {server.name} is not cleaned up: {error}") from error
        except SSHError as through:
            log.warning("server %s: not reached through %s: %s", server.name, target.name, through)
            try:
                with self._executor(server) as direct:
                    remote.clean_up(direct, server, keys)
            except SSHError as error:
                raise ServerCleanupError(
                    f"server {server.name} is not cleaned up: through {target.name}: {through}; "
                    f"at its own address {server.address}: {error}"
                ) from error
        with self._state.transaction() as state:
            current = state.claims.get(claim.server)
            if current is not None and current.node == node.name:
                del state.claims[claim.server]
            state.pending_cleanups.pop(claim.server, None)
        return True

    def ex_clean_up_released(self) -> dict[str, str]:
        """Retry the cleanup of free servers released without one; return those still pending."""
        pending = self._state.read().pending_cleanups
        still: dict[str, str] = {}
        for name, cleanup in sorted(pending.items()):
            server = self.inventory.server(name)
            if server is None:
                still[name] = cleanup.warning
                continue
            try:
                with self._executor(server) as executor:
                    remote.clean_up(executor, server, cleanup.public_keys)
            except SSHError as error:
                still[name] = f"server {name} is still not cleaned up: {error}"
                log.warning("%s", still[name])
            with self._state.transaction() as state:
                current = state.pending_cleanups.get(name)
                # Claimed again meanwhile: that claim cleans up before it prepares.
                if current is None or name in state.claims:
                    continue
                if name in still:
                    current.warning = still[name]
                else:
                    del state.pending_cleanups[name]
        return still

    def list_nodes(self) -> list[Node]:
        """Return a node per claimed server, rediscovered from state_dir."""
        claims = self._state.read().claims.values()
        return [to_node(self, claim) for claim in sorted(claims, key=lambda c: c.node)]

    def ex_list_servers(self) -> list[dict[str, Any]]:
        """Return every inventory server with its status (free or claimed), never its key."""
        state = self._state.read()
        return [server_status(server, state) for server in self.inventory.servers]

    def ex_ssh_route(self, node: Node) -> Route:
        """Return the way to the node's server once its constellation's firewall is up.

        A server without a public address is reached as a cloud's private machine is: through
        the constellation's public machine, at its LAN address (a kind may seal it, e.g. vrc's
        sim takes SSH from the router only). The inventory's own way in (address, proxy)
        serves to claim and prepare the server, before that firewall.
        """
        server = self._server(str(node.id))
        if server.public_ip is None:
            return Route(
                host=node.private_ips[0],
                user=server.user,
                port=server.port,
                jump=BEHIND_PUBLIC_MACHINE,
            )
        if server.proxy_command:
            return Route(
                host=node.private_ips[0],
                user=server.user,
                port=server.port,
                proxy_command=tuple(server.proxy_command),
            )
        return Route(host=server.address, user=server.user, port=server.port)

    def ex_public_proxy_command(self, ip: str, port: int) -> list[str] | None:
        """Return how "the internet" reaches ip:port: a server's public address through the
        inventory's proxy to it, an inventory server's private address not at all (the
        internet has no route to it, whatever the controller's own way in); None: from here."""
        for server in self.inventory.servers:
            if ip == server.public_ip and server.proxy_command and port == server.port:
                return list(server.proxy_command)
        public = {server.public_ip for server in self.inventory.servers}
        private = {server.private_ip for server in self.inventory.servers}
        if ip in private and ip not in public and ipaddress.ip_address(ip).is_private:
            return list(UNROUTABLE)
        return None

    def list_sizes(self, location: NodeLocation | None = None) -> list[NodeSize]:
        """Return the single size: whatever the server has."""
        return [NodeSize(EXISTING, EXISTING, ram=0, disk=0, bandwidth=None, price=0.0, driver=self)]

    def list_images(self, location: NodeLocation | None = None) -> list[NodeImage]:
        """Return the single image: the system already on the server."""
        return [NodeImage(id=EXISTING, name=EXISTING, driver=self)]

    def list_locations(self) -> list[NodeLocation]:
        """Return the single location: wherever the inventory's servers are."""
        return [NodeLocation(id=LOCATION_ID, name=LOCATION_ID, country="", driver=self)]

    # -- internals -----------------------------------------------------------------------------

    def _server(self, name: str) -> Server:
        server = self.inventory.server(name)
        if server is None:
            raise ServersProviderError(f"server {name!r} is claimed but not in the inventory")
        return server

    def _executor(self, server: Server) -> SSHExecutor:
        return SSHExecutor(
            self._host_keys,
            log_sink=_log_line,
            secrets=[server.private_key],
            connect_policy=ConnectPolicy(
                deadline=self.connect_timeout, attempt_timeout=min(10.0, self.connect_timeout)
            ),
        )

    def _known_host_key(self, server_name: str) -> str | None:
        server = self.inventory.server(server_name)
        if server is not None and server.host_key is not None:
            return server.host_key
        return self._state.read().host_keys.get(server_name)

    def _record_host_key(self, server_name: str, key_type_and_base64: str) -> None:
        with self._state.transaction() as state:
            state.host_keys.setdefault(server_name, key_type_and_base64)

    def _mark_failed(self, server_name: str, node_name: str, error: str) -> None:
        with self._state.transaction() as state:
            claim = state.claims.get(server_name)
            if claim is not None and claim.node == node_name:
                claim.status, claim.error = STATUS_FAILED, error


def _log_line(machine_name: str, line: str) -> None:
    log.debug("%s: %s", machine_name, line)
