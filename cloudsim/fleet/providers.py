"""Build the libcloud driver for a provider name from the app's configuration."""

from __future__ import annotations

from typing import Any, Protocol, cast

from libcloud.compute.base import Node, NodeImage, NodeSize

from cloudsim.config import Config
from cloudsim.errors import InvalidInput

PROVIDERS = ("local",)


class NetworkDriver(Protocol):
    """A libcloud NodeDriver with CloudSim's network extensions (our local and EC2 drivers)."""

    def list_nodes(self) -> list[Node]: ...
    def list_sizes(self) -> list[NodeSize]: ...
    def list_images(self) -> list[NodeImage]: ...
    def create_node(self, **kwargs: Any) -> Node: ...
    def destroy_node(self, node: Node) -> bool: ...
    def ex_create_network(self, name: str, cidr: str | None = None) -> Any: ...
    def ex_get_network(self, name: str) -> Any: ...
    def ex_list_networks(self) -> list[Any]: ...
    def ex_destroy_network(self, network: Any) -> bool: ...


def make_driver(provider: str, config: Config) -> NetworkDriver:
    """Return a driver for `provider`; every provider is a libcloud NodeDriver."""
    if provider == "local":
        from provisioners.local import register
        from provisioners.local.driver import LocalNodeDriver

        register()
        return cast(
            NetworkDriver,
            LocalNodeDriver(
                state_dir=str(config.instance_dir / "local-hosts"),
                subnet_pool=config.local_subnet_pool,
                public_cidr=config.local_public_cidr,
                prefix=config.local_prefix,
                hidden_paths=(str(config.instance_dir),),
            ),
        )
    raise InvalidInput(f"unknown provider {provider!r}; known: {', '.join(PROVIDERS)}")
