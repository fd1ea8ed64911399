"""Providers: a libcloud driver plus what CloudSim needs around it (sizes, image, node lookup).

`local` needs no settings. Cloud providers keep theirs (credentials included) encrypted in the
database, set by an admin with `cloudsim provider configure`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

from libcloud.compute.base import Node, NodeDriver, NodeImage, NodeSize
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Secret, SecretKind

PROVIDERS = ("local", "ec2", "servers")
SETTINGS_PREFIX = "provider:"
EC2_FIELDS = ("access_key", "secret_key", "region", "image", "sizes", "endpoint")


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


@dataclass
class Provider:
    """A driver, with how to pick sizes and the image, and how to find a constellation's nodes."""

    name: str
    driver: NetworkDriver
    sizes: dict[str, str] = field(default_factory=dict)
    image_id: str | None = None
    # argv reaching ip:port from "the internet", where the provider can simulate one (local)
    public_probe: Callable[[str, int], list[str]] | None = None

    def size(self, logical: str) -> NodeSize:
        """Return the provider size for a logical size ("small", "gpu", ...)."""
        wanted = self.sizes.get(logical) or self.sizes.get("default")
        if wanted is None:
            return self.driver.list_sizes()[0]
        return NodeSize(
            id=wanted,
            name=wanted,
            ram=0,
            disk=0,
            bandwidth=0,
            price=0,
            driver=cast(NodeDriver, self.driver),
        )

    def image(self) -> NodeImage:
        """Return the machine image every machine starts from."""
        if self.image_id is None:
            return self.driver.list_images()[0]
        return NodeImage(id=self.image_id, name=self.image_id, driver=cast(NodeDriver, self.driver))

    def nodes(self, constellation: str | None = None) -> list[Node]:
        """Return the live nodes CloudSim made (of one constellation, when named)."""
        by_tags = getattr(self.driver, "ex_list_nodes_by_tags", None)
        if by_tags is not None:
            nodes = by_tags({"cloudsim:constellation": constellation} if constellation else {})
        else:
            nodes = self.driver.list_nodes()
        return [
            node
            for node in nodes
            if constellation is None
            or node.extra.get("tags", {}).get("cloudsim:constellation") == constellation
        ]


def open_provider(name: str, config: Config) -> Provider:
    """Return the provider called name, configured from the app and its stored settings."""
    if name == "local":
        from provisioners.local import register
        from provisioners.local.driver import LocalNodeDriver

        register()
        driver = LocalNodeDriver(
            state_dir=str(config.instance_dir / "local-hosts"),
            subnet_pool=config.local_subnet_pool,
            public_cidr=config.local_public_cidr,
            prefix=config.local_prefix,
            hidden_paths=(str(config.instance_dir),),
        )
        return Provider(
            "local", cast(NetworkDriver, driver), public_probe=driver.ex_public_proxy_command
        )
    if name == "ec2":
        from provisioners.ec2 import register as register_ec2
        from provisioners.ec2.driver import CloudSimEC2NodeDriver

        register_ec2()
        settings = provider_settings("ec2")
        endpoint = _endpoint(settings.get("endpoint"))
        ec2 = CloudSimEC2NodeDriver(
            settings["access_key"], settings["secret_key"], region=settings["region"], **endpoint
        )
        return Provider(
            "ec2",
            cast(NetworkDriver, ec2),
            sizes=settings.get("sizes") or {},
            image_id=settings["image"],
        )
    if name == "servers":
        from provisioners.servers import register as register_servers
        from provisioners.servers.driver import ServersNodeDriver

        register_servers()
        servers = ServersNodeDriver(
            inventory=provider_settings("servers")["inventory"],
            state_dir=str(config.instance_dir / "servers"),
        )
        return Provider("servers", cast(NetworkDriver, servers))
    raise InvalidInput(f"unknown provider {name!r}; known: {', '.join(PROVIDERS)}")


def _endpoint(url: str | None) -> dict[str, Any]:
    """Turn an endpoint URL (an EC2-compatible API such as a test server) into driver options."""
    if not url:
        return {}
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise InvalidInput(f"endpoint must be an http(s) URL, got {url!r}")
    return {"host": parts.hostname, "port": parts.port, "secure": parts.scheme == "https"}


def _check_ec2(settings: dict[str, Any]) -> None:
    missing = [
        key for key in ("access_key", "secret_key", "region", "image") if not settings.get(key)
    ]
    if missing:
        raise InvalidInput(f"ec2 needs {', '.join(missing)}")
    unknown = sorted(set(settings) - set(EC2_FIELDS))
    if unknown:
        raise InvalidInput(f"unknown ec2 settings: {', '.join(unknown)}")
    _endpoint(settings.get("endpoint"))


def _check_servers(settings: dict[str, Any]) -> None:
    from provisioners.servers.errors import ServersProviderError
    from provisioners.servers.inventory import Inventory

    if set(settings) != {"inventory"}:
        raise InvalidInput("servers settings are {'inventory': [...server entries...]}")
    try:
        Inventory.of(settings["inventory"])
    except (ServersProviderError, TypeError, ValueError) as exc:
        raise InvalidInput(f"servers inventory: {exc}") from None


def provider_settings(name: str) -> dict[str, Any]:
    """Return a provider's stored settings, or say how to configure them."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "installation", Secret.name == SETTINGS_PREFIX + name
        )
    )
    if secret is None:
        raise InvalidInput(
            f"provider {name} is not configured: an admin runs "
            f"`cloudsim provider configure {name} ...`"
        )
    return cast(dict[str, Any], json.loads(secret.value))


def configure_provider(name: str, settings: dict[str, Any]) -> None:
    """Store (encrypted) a provider's settings, replacing earlier ones; refuse bad ones."""
    if name == "ec2":
        _check_ec2(settings)
    elif name == "servers":
        _check_servers(settings)
    else:
        raise InvalidInput(f"provider {name!r} takes no settings; configurable: ec2, servers")
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "installation", Secret.name == SETTINGS_PREFIX + name
        )
    )
    if secret is None:
        secret = Secret(
            kind=SecretKind.CLOUD_CREDENTIALS,
            owner_type="installation",
            name=SETTINGS_PREFIX + name,
            value="",
        )
        db.session.add(secret)
    secret.value = json.dumps(settings)
    db.session.commit()
