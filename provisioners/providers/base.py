"""The driver every provider implements: libcloud's NodeDriver plus CloudSim's extensions.

The launch job calls only what is declared here. The network calls have no default (every
provider has networks of its own); the rest do, so a provider implements only what it
really has: security groups (ex_apply_firewall), a simulated internet
(ex_public_proxy_command), its own way in (ex_ssh_route).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from libcloud.compute.base import (
    Node,
    NodeAuthPassword,
    NodeAuthSSHKey,
    NodeDriver,
    NodeImage,
    NodeLocation,
    NodeSize,
)
from libcloud.compute.types import NodeState

from provisioners.providers.capacity import Capacity, Demand
from provisioners.providers.errors import ProviderError
from provisioners.remote.firewall import FirewallRule
from provisioners.remote.ssh import Route

# Route.jump of a machine reached through its group's public machine (no machine's name)
BEHIND_PUBLIC_MACHINE = "<public machine>"
WAITING = (NodeState.PENDING, NodeState.STARTING, NodeState.REBOOTING)
SSH_INTERFACES = ("public_ips", "private_ips")


@dataclass
class ProviderNetwork:
    """A constellation's private network, as ex_create_network returns it and
    create_node(ex_network=...) takes it; each provider keeps its own details in extra."""

    id: str
    name: str
    cidr: str
    gateway: str | None  # the address the machines route through, None: the provider's own
    driver: Any = field(repr=False, compare=False)
    extra: dict[str, Any] = field(default_factory=dict)


class CloudSimNodeDriver(NodeDriver):  # type: ignore[misc]
    """A libcloud NodeDriver with the network extensions and defaults CloudSim relies on."""

    # the class a driver's own errors derive from, for the errors raised here
    error_class: type[ProviderError] = ProviderError
    # machines are created with the constellation's SSH key (libcloud's feature list)
    features = {"create_node": ["ssh_key"]}

    # -- what every provider has its own way of doing ------------------------------------------

    def create_node(
        self,
        name: str,
        size: NodeSize | None = None,
        image: NodeImage | None = None,
        location: NodeLocation | None = None,
        auth: NodeAuthSSHKey | NodeAuthPassword | None = None,
        ex_network: Any = None,
        ex_private_ip: str | None = None,
        ex_public: bool = False,
        ex_tags: dict[str, str] | None = None,
    ) -> Node:
        """Create a machine in ex_network at ex_private_ip, with a public address if ex_public.

        A node of that name that exists already is returned as it is (launches resume).
        """
        raise NotImplementedError

    def ex_create_network(self, name: str, cidr: str | None = None) -> ProviderNetwork:
        """Create the named private network (or return it when it exists)."""
        raise NotImplementedError

    def ex_list_networks(self) -> Sequence[ProviderNetwork]:
        """Return the networks this driver made."""
        raise NotImplementedError

    def ex_get_network(self, name: str) -> ProviderNetwork:
        """Return the named network, or raise the driver's NetworkNotFoundError."""
        raise NotImplementedError

    def ex_destroy_network(self, network: Any) -> bool:
        """Destroy a network no node uses any more; True also when it was gone."""
        raise NotImplementedError

    # -- defaults ------------------------------------------------------------------------------

    def ex_apply_firewall(
        self, network: Any, rules: Sequence[FirewallRule], roles: Sequence[str]
    ) -> dict[str, str]:
        """Express the rules in the provider's own firewall; return role -> its group id.

        Without one (the default) the machines' host firewalls carry the rules alone.
        """
        return {}

    def ex_prepare(self) -> list[str]:
        """Make ready what every machine of this provider shares; return what changed."""
        return []

    def ex_image_layer(self, name: str, command: str) -> bool | None:
        """Install once, for every machine made afterwards, what command (bash, as root)
        installs; True: made now, False: it existed, None: this provider cannot (default)."""
        return None

    def ex_capacity(self, pending: Demand | None = None) -> Capacity | None:
        """Return what the provider can still take beyond pending; None: it does not know."""
        return None

    def ex_list_nodes_by_tags(self, tags: Mapping[str, str]) -> list[Node]:
        """Return the nodes carrying every one of tags (all nodes for no tags)."""
        return [
            node
            for node in self.list_nodes()
            if all(node.extra.get("tags", {}).get(key) == value for key, value in tags.items())
        ]

    def ex_public_proxy_command(self, ip: str, port: int) -> list[str] | None:
        """Return an argv connecting stdio to ip:port from "the internet", None: from here."""
        return None

    def ex_public_command(self, argv: list[str]) -> list[str] | None:
        """Return argv wrapped to run on "the internet", None: there is no such place to run."""
        return None

    def ex_destroy_node_through(self, node: Node, executor: Any, target: Any) -> bool:
        """Destroy node, cleaning it through the caller's SSH route where the provider cleans
        machines (executor: an SSHExecutor, target: the SSHTarget a launch uses).

        Providers whose machines vanish with the node (clouds, local hosts) ignore the route.
        A provider that cannot clean the machine raises and keeps it: a retry finds it again.
        """
        return bool(self.destroy_node(node))

    def ex_ssh_route(self, node: Node) -> Route:
        """Return how the controller reaches node: a public address, else through a jump host."""
        if node.public_ips:
            return Route(host=node.public_ips[0])
        return Route(host=node.private_ips[0], jump=BEHIND_PUBLIC_MACHINE)

    def wait_until_running(
        self,
        nodes: list[Node],
        wait_period: float = 0.5,
        timeout: float = 600,
        ssh_interface: str = "private_ips",
        force_ipv4: bool = True,
        ex_list_nodes_kwargs: dict[str, Any] | None = None,
    ) -> list[tuple[Node, list[str]]]:
        """Wait until every node runs; fail at once for a node that never will.

        The default interface is "private_ips" (unlike libcloud's "public_ips"): CloudSim's
        machines mostly have no public address.
        """
        if ssh_interface not in SSH_INTERFACES:
            raise self.error_class(f"ssh_interface must be one of {', '.join(SSH_INTERFACES)}")
        deadline = time.monotonic() + timeout
        while True:
            current = {node.id: node for node in self.list_nodes()}
            states = [(node, current.get(node.id)) for node in nodes]
            hopeless = [
                f"{node.name} ({'gone' if now is None else now.state})"
                for node, now in states
                if now is None
                or now.state not in (NodeState.RUNNING, *WAITING)
                or (now.state == NodeState.RUNNING and not getattr(now, ssh_interface))
            ]
            if hopeless:
                raise self.error_class(
                    f"nodes that will not run with {ssh_interface}: {', '.join(hopeless)}"
                )
            running = [now for _node, now in states if now is not None]
            if all(now.state == NodeState.RUNNING for now in running):
                return [(now, list(getattr(now, ssh_interface))) for now in running]
            if time.monotonic() >= deadline:
                raise self.error_class(f"nodes still pending after {timeout:.0f} s")
            time.sleep(wait_period)
