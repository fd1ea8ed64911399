"""The EC2 provider: libcloud's EC2 driver extended with CloudSim's network and firewall calls."""

from typing import cast

from libcloud.compute.providers import DRIVERS, set_driver

PROVIDER_NAME = "cloudsim-ec2"
DRIVER_MODULE = "provisioners.ec2.driver"
DRIVER_CLASS = "CloudSimEC2NodeDriver"


def register() -> None:
    """Register the driver with libcloud as provider "cloudsim-ec2" (safe to call repeatedly)."""
    registered = cast(dict[str, tuple[str, str]], DRIVERS).get(PROVIDER_NAME)
    if registered is None:
        # libcloud's annotations say module/class objects; it takes (and stores) names.
        set_driver(PROVIDER_NAME, DRIVER_MODULE, DRIVER_CLASS)  # type: ignore[arg-type]
    elif tuple(registered) != (DRIVER_MODULE, DRIVER_CLASS):
        raise RuntimeError(f"libcloud provider {PROVIDER_NAME!r} is already {registered!r}")
