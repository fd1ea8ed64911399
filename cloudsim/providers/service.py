"""Providers as the launch job uses them: a driver from the registry, sizes, image, settings.

The providers themselves, with their settings checks, are `provisioners.providers.registry`.
`local` is configured from the app's settings; the others keep theirs (credentials included)
encrypted in the database, set by an admin with `cloudsim provider configure`.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, cast

from libcloud.compute.base import Node, NodeImage, NodeSize
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.documents import load_document
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Secret, SecretKind, utcnow
from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.errors import SettingsError
from provisioners.providers.registry import PROVIDERS as REGISTRY
from provisioners.providers.registry import ProviderSpec, provider

PROVIDERS = tuple(REGISTRY)
SETTINGS_PREFIX = "provider:"
INSTALLATION = ("installation", 0)  # the owner of the settings every launch here uses
CONSTELLATION_TAG = "cloudsim:constellation"


@dataclass
class Provider:
    """A driver, with how to pick sizes and the image, and how to find a constellation's nodes."""

    name: str
    driver: CloudSimNodeDriver
    sizes: dict[str, str] = field(default_factory=dict)
    image_id: str | None = None

    def size(self, logical: str) -> NodeSize:
        """Return the provider size for a logical size ("small", "gpu", ...)."""
        wanted = self.sizes.get(logical) or self.sizes.get("default")
        if wanted is None:
            return self.driver.list_sizes()[0]
        return NodeSize(
            id=wanted, name=wanted, ram=0, disk=0, bandwidth=0, price=0, driver=self.driver
        )

    def image(self) -> NodeImage:
        """Return the machine image every machine starts from."""
        if self.image_id is None:
            return self.driver.list_images()[0]
        return NodeImage(id=self.image_id, name=self.image_id, driver=self.driver)

    def nodes(self, constellation: str | None = None) -> list[Node]:
        """Return the live nodes CloudSim made (of one constellation, when named)."""
        if constellation is not None:
            return self.driver.ex_list_nodes_by_tags({CONSTELLATION_TAG: constellation})
        return [n for n in self.driver.list_nodes() if CONSTELLATION_TAG in n.extra.get("tags", {})]


def _spec(name: str) -> ProviderSpec:
    try:
        return provider(name)
    except SettingsError as exc:
        raise InvalidInput(str(exc)) from None


def open_provider(name: str, config: Config) -> Provider:
    """Return the provider called name, configured from the app and its stored settings."""
    spec = _spec(name)
    if spec.configurable:
        settings = provider_settings(name)
    else:
        settings = {
            "subnet_pool": config.local_subnet_pool,
            "public_cidr": config.local_public_cidr,
            "prefix": config.local_prefix,
            "hidden_paths": (str(config.instance_dir),),
            "max_hosts": config.local_max_hosts,
            "host_memory_mib": config.local_host_memory_mb,
            "memory_reserve_mib": config.local_memory_reserve_mb,
        }
    try:
        driver = spec.open(settings, config.instance_dir)
    except SettingsError as exc:
        raise InvalidInput(str(exc)) from None
    return Provider(
        name, driver, sizes=dict(settings.get("sizes") or {}), image_id=settings.get("image")
    )


def provider_settings(name: str) -> dict[str, Any]:
    """Return a provider's stored settings, or say how to configure them."""
    secret = stored_settings(name)
    if secret is None:
        raise InvalidInput(
            f"provider {name} is not configured: an admin runs "
            f"`cloudsim provider configure {name} ...`"
        )
    return cast(dict[str, Any], json.loads(secret.value))


def servers_settings(inventory: str | bytes, where: str) -> dict[str, Any]:
    """Return the servers provider's settings from an inventory's YAML; refuse what is not YAML."""
    return {"inventory": load_document(inventory, where, not_parsed="{what}: not YAML")}


def ec2_settings(
    *,
    access_key: str,
    secret_key: str,
    region: str,
    image: str,
    sizes: Iterable[str],
    endpoint: str | None = None,
) -> dict[str, Any]:
    """Return ec2's settings from its fields, sizes as LOGICAL=TYPE items (blank ones skipped)."""
    size_map = {}
    for item in (i.strip() for i in sizes):
        if not item:
            continue
        logical, _, instance_type = item.partition("=")
        if not logical or not instance_type:
            raise InvalidInput(f"{item!r} is not LOGICAL=TYPE")
        size_map[logical] = instance_type
    settings: dict[str, Any] = {
        "access_key": access_key,
        "secret_key": secret_key,
        "region": region,
        "image": image,
        "sizes": size_map,
    }
    if endpoint:
        settings["endpoint"] = endpoint
    return settings


def check_settings(name: str, settings: dict[str, Any]) -> None:
    """Refuse (InvalidInput) settings the provider called name does not take."""
    spec = _spec(name)
    if not spec.configurable:
        configurable = ", ".join(p.name for p in REGISTRY.values() if p.configurable)
        raise InvalidInput(f"provider {name!r} takes no settings; configurable: {configurable}")
    try:
        spec.check(settings)
    except SettingsError as exc:
        raise InvalidInput(str(exc)) from None


def configure_provider(
    name: str, settings: dict[str, Any], owner: tuple[str, int] = INSTALLATION
) -> None:
    """Store (encrypted) a provider's settings, the installation's or an owner's (a team
    instance's), replacing earlier ones; refuse bad ones."""
    check_settings(name, settings)
    secret = stored_settings(name, owner)
    if secret is None:
        secret = Secret(
            kind=SecretKind.CLOUD_CREDENTIALS,
            owner_type=owner[0],
            owner_id=owner[1],
            name=SETTINGS_PREFIX + name,
            value="",
        )
        db.session.add(secret)
    secret.value = json.dumps(settings)
    secret.created_at = utcnow()  # when these settings were set, as a team instance's page says
    db.session.flush()


def stored_settings(name: str, owner: tuple[str, int] = INSTALLATION) -> Secret | None:
    """Return the secret holding a provider's settings (the installation's or an owner's)."""
    return db.session.scalar(
        select(Secret).where(
            Secret.owner_type == owner[0],
            Secret.owner_id == owner[1],
            Secret.name == SETTINGS_PREFIX + name,
        )
    )
