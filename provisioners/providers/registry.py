"""The providers, in one table: the libcloud driver of each, its settings and their checks.

Every driver is registered with libcloud under its provider name and opened through
libcloud's `get_driver`, so adding a provider means adding a row here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from libcloud.compute.providers import DRIVERS, get_driver, set_driver

from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.ec2 import settings as ec2_settings
from provisioners.providers.errors import SettingsError
from provisioners.providers.servers.errors import ServersProviderError
from provisioners.providers.servers.inventory import Inventory

Settings = Mapping[str, Any]
# the local provider's settings come from the app's configuration, never from an admin
LOCAL_SETTINGS = (
    "subnet_pool",
    "public_cidr",
    "prefix",
    "hidden_paths",
    "max_hosts",
    "host_memory_mib",
    "memory_reserve_mib",
)


@dataclass(frozen=True)
class ProviderSpec:
    """A provider: its driver, whether an admin configures it, how settings become arguments."""

    name: str
    libcloud_name: str  # libcloud has an "ec2" of its own
    driver_module: str
    driver_class: str
    configurable: bool  # settings stored by an admin; otherwise they come from the app
    check: Callable[[Settings], None]
    arguments: Callable[[Settings], dict[str, Any]]
    state_folder: str | None  # where, under the app's folder, the driver records what it made

    def open(self, settings: Settings, instance_dir: Path) -> CloudSimNodeDriver:
        """Return the driver, configured from checked settings (its state under instance_dir)."""
        self.check(settings)
        register_drivers()
        arguments = self.arguments(settings)
        if self.state_folder is not None:
            arguments["state_dir"] = str(instance_dir / self.state_folder)
        driver = get_driver(cast(Any, self.libcloud_name))(**arguments)
        return cast(CloudSimNodeDriver, driver)


def _check_local(settings: Settings) -> None:
    unknown = sorted(set(settings) - set(LOCAL_SETTINGS))
    if unknown:
        raise SettingsError(f"unknown local settings: {', '.join(unknown)}")


def _check_servers(settings: Settings) -> None:
    if set(settings) != {"inventory"}:
        raise SettingsError("servers settings are {'inventory': [...server entries...]}")
    try:
        Inventory.of(settings["inventory"])
    except (ServersProviderError, TypeError, ValueError) as exc:
        raise SettingsError(f"servers inventory: {exc}") from None


PROVIDERS: dict[str, ProviderSpec] = {
    spec.name: spec
    for spec in (
        ProviderSpec(
            name="local",
            libcloud_name="local",
            driver_module="provisioners.providers.local.driver",
            driver_class="LocalNodeDriver",
            configurable=False,
            check=_check_local,
            arguments=dict,
            state_folder="local-hosts",
        ),
        ProviderSpec(
            name="ec2",
            libcloud_name="cloudsim-ec2",
            driver_module="provisioners.providers.ec2.driver",
            driver_class="CloudSimEC2NodeDriver",
            configurable=True,
            check=ec2_settings.check,
            arguments=ec2_settings.driver_arguments,
            state_folder=None,
        ),
        ProviderSpec(
            name="servers",
            libcloud_name="servers",
            driver_module="provisioners.providers.servers.driver",
            driver_class="ServersNodeDriver",
            configurable=True,
            check=_check_servers,
            arguments=lambda settings: {"inventory": settings["inventory"]},
            state_folder="servers",
        ),
    )
}


def provider(name: str) -> ProviderSpec:
    """Return the named provider, or raise SettingsError listing the known ones."""
    spec = PROVIDERS.get(name)
    if spec is None:
        raise SettingsError(f"unknown provider {name!r}; known: {', '.join(PROVIDERS)}")
    return spec


def register_drivers() -> None:
    """Register every provider's driver with libcloud under its name (safe to repeat)."""
    registered = cast(dict[str, tuple[str, str]], DRIVERS)
    for spec in PROVIDERS.values():
        wanted = (spec.driver_module, spec.driver_class)
        current = registered.get(spec.libcloud_name)
        if current is None:
            # libcloud's annotations say module/class objects; it takes (and stores) names.
            set_driver(spec.libcloud_name, *wanted)  # type: ignore[arg-type]
        elif tuple(current) != wanted:
            raise RuntimeError(f"libcloud provider {spec.libcloud_name!r} is already {current!r}")
