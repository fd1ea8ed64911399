"""libcloud objects (networks, nodes) and status rows made from claims and the inventory."""

from __future__ import annotations

import datetime
from typing import TYPE_CHECKING, Any

from libcloud.compute.base import Node

from provisioners.providers.base import ProviderNetwork
from provisioners.providers.servers.claims import node_state
from provisioners.providers.servers.inventory import Server
from provisioners.providers.servers.state import NetworkClaim, ServerClaim, ServersState

if TYPE_CHECKING:
    from provisioners.providers.servers.driver import ServersNodeDriver


class ServersNetwork(ProviderNetwork):
    """A pre-made LAN in use under a network name, as handed to create_node(ex_network=...)."""


def to_network(driver: ServersNodeDriver, claim: NetworkClaim) -> ServersNetwork:
    """Return the network object of a network claim."""
    return ServersNetwork(
        id=claim.name,
        name=claim.name,
        cidr=claim.cidr,
        gateway=None,  # the LAN's own, as the servers are set up
        driver=driver,
        extra={"lan": claim.lan, "created_at": claim.created_at},
    )


def to_node(driver: ServersNodeDriver, claim: ServerClaim) -> Node:
    """Return the node of a server claim; its addresses are the server's own."""
    server = driver.inventory.server(claim.server)
    extra: dict[str, Any] = {
        "server": claim.server,
        "network": claim.network,
        "tags": dict(claim.tags),
        "status": claim.status,
        "error": claim.error,
        # How the provider itself logs in; the engine reaches nodes by their addresses.
        "ssh_user": server.user if server else None,
        "ssh_address": server.address if server else None,
        "ssh_port": server.port if server else None,
        "capabilities": sorted(server.capabilities) if server else [],
    }
    if server is not None and server.proxy_command:
        extra["ssh_proxy_command"] = list(server.proxy_command)
    return Node(
        id=claim.server,
        name=claim.node,
        state=node_state(claim),
        public_ips=[claim.public_ip] if claim.public_ip else [],
        private_ips=[claim.private_ip],
        driver=driver,
        size=driver.list_sizes()[0],
        image=driver.list_images()[0],
        created_at=datetime.datetime.fromtimestamp(claim.created_at, tz=datetime.UTC),
        extra=extra,
    )


def server_status(server: Server, state: ServersState) -> dict[str, Any]:
    """Return what the app shows about one server: where it is, whether and by whom claimed."""
    claim = state.claims.get(server.name)
    pending = state.pending_cleanups.get(server.name)
    return {
        "name": server.name,
        "address": server.address,
        "private_ip": server.private_ip,
        "public_ip": server.public_ip,
        "network": server.network,
        "cidr": server.cidr,
        "user": server.user,
        "capabilities": sorted(server.capabilities),
        "status": "free" if claim is None else "claimed",
        "node": claim.node if claim else None,
        "node_state": node_state(claim).value if claim else None,
        "tags": dict(claim.tags) if claim else {},
        "warning": pending.warning if pending else None,
    }
