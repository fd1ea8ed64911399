"""The `local` provider: real hosts on this machine, as an apache-libcloud NodeDriver."""

from typing import cast

from libcloud.compute.providers import DRIVERS, set_driver

PROVIDER_NAME = "local"
DRIVER_MODULE = "provisioners.local.driver"
DRIVER_CLASS = "LocalNodeDriver"


def register() -> None:
    """Register the driver with libcloud as provider "local" (safe to call repeatedly)."""
    registered = cast(dict[str, tuple[str, str]], DRIVERS).get(PROVIDER_NAME)
    if registered is None:
        # libcloud's annotations say module/class objects; it takes (and stores) names.
        set_driver(PROVIDER_NAME, DRIVER_MODULE, DRIVER_CLASS)  # type: ignore[arg-type]
    elif tuple(registered) != (DRIVER_MODULE, DRIVER_CLASS):
        raise RuntimeError(f"libcloud provider {PROVIDER_NAME!r} is already {registered!r}")
