"""Pure decisions about claims: which server fits a request, which network is free, node state."""

from __future__ import annotations

import re
from collections.abc import Mapping

from libcloud.compute.types import NodeState

from provisioners.providers.servers.errors import InvalidRequestError, NoFreeServerError
from provisioners.providers.servers.inventory import Inventory, Server
from provisioners.providers.servers.state import (
    STATUS_PREPARING,
    STATUS_READY,
    NetworkClaim,
    ServerClaim,
    ServersState,
)

# A node's name becomes its server's hostname while claimed.
_NODE_NAME = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?$")
_NETWORK_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,62}$")


def check_node_name(name: str) -> str:
    """Return name if it can serve as a hostname, else raise InvalidRequestError."""
    if not isinstance(name, str) or not _NODE_NAME.match(name):
        raise InvalidRequestError(
            f"invalid node name {name!r}: it becomes the hostname, so 1-63 letters, digits "
            "and '-', not starting or ending with '-'"
        )
    return name


def check_network_name(name: str) -> str:
    """Return name if it is a word usable as a network name, else raise InvalidRequestError."""
    if not isinstance(name, str) or not _NETWORK_NAME.match(name):
        raise InvalidRequestError(
            f"invalid network name {name!r}: 1-63 letters, digits, '_', '.' and '-'"
        )
    return name


def check_tags(tags: Mapping[str, str] | None) -> dict[str, str]:
    """Return tags as a plain dict of str to str, else raise InvalidRequestError."""
    checked = dict(tags or {})
    for key, value in checked.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InvalidRequestError(f"ex_tags must map str to str (got {key!r}: {value!r})")
    return checked


def free_lan(
    inventory: Inventory, state: ServersState, network_name: str, cidr: str | None
) -> tuple[str, str]:
    """Return (lan, cidr) of a pre-made network no one uses whose servers are all free."""
    in_use = {claim.lan for claim in state.networks.values()}
    for lan, lan_cidr in inventory.networks().items():
        if lan in in_use or (cidr is not None and cidr != lan_cidr):
            continue
        if any(server.name in state.claims for server in inventory.in_network(lan)):
            continue
        return lan, lan_cidr
    wanted = f" on {cidr}" if cidr is not None else ""
    raise NoFreeServerError(
        f"no free pre-made network{wanted} for {network_name!r}: the inventory's networks "
        f"({', '.join(sorted(inventory.networks())) or 'none'}) are all in use or have "
        "claimed servers"
    )


def choose_server(
    inventory: Inventory,
    state: ServersState,
    network: NetworkClaim,
    *,
    private_ip: str | None,
    public: bool,
    capability: str | None,
) -> Server:
    """Return the free server of network's LAN that fits best, or raise NoFreeServerError.

    A server whose private_ip matches is preferred; a request without ex_public prefers
    servers without a public address, so that the machines claimed alongside it in parallel
    (a router) still find one.
    """
    members = inventory.in_network(network.lan)
    fitting = [
        server
        for server in members
        if server.name not in state.claims
        and (not public or server.public_ip is not None)
        and (capability is None or capability in server.capabilities)
    ]
    if not fitting:
        needs = [
            *(["a public IP"] if public else []),
            *([f"capability {capability!r}"] if capability else []),
        ]
        claimed = sorted(s.name for s in members if s.name in state.claims)
        raise NoFreeServerError(
            f"no free server{' with ' + ' and '.join(needs) if needs else ''} in network "
            f"{network.name!r} (pre-made network {network.lan!r}: {len(members)} server(s), "
            f"claimed: {', '.join(claimed) or 'none'})"
        )

    def preference(server: Server) -> tuple[bool, bool]:
        exact = private_ip is not None and server.private_ip == private_ip
        return (not public and server.public_ip is not None, not exact)

    return min(fitting, key=preference)  # min keeps inventory order among equals


def node_state(claim: ServerClaim) -> NodeState:
    """Return the libcloud state of a claim: running once prepared, pending while being so."""
    if claim.status == STATUS_READY:
        return NodeState.RUNNING
    if claim.status == STATUS_PREPARING and claim.creator.alive():
        return NodeState.PENDING
    return NodeState.ERROR  # preparation failed, or the process preparing it died
