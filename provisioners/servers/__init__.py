"""The `servers` provider: machines that already exist, as an apache-libcloud NodeDriver.

An inventory lists the servers (address, SSH login, LAN and its CIDR). Networks are the
inventory's pre-made LANs: ex_create_network hands out one whose servers are all free.
create_node claims a free server of that LAN and, over SSH with the inventory's key, sets
its hostname to the node's name and installs the node's public key; destroy_node removes
what CloudSim put there (keys, services, CLOUDSIM-* chains, its files), puts back the
server's /etc/hosts, /etc/motd, default route, firewall and ip_forward, its own hostname, and
frees it. A server that cannot be cleaned up is freed anyway (terminate must finish) with a
warning in the state, and is cleaned before its next claim. Claims live in a JSON file under
state_dir, so any later driver rediscovers them. See README.md. Modules: driver (the
libcloud API), inventory, claims (choosing servers), remote (the SSH work), state,
nodes (libcloud objects from claims), hostkeys.
"""

from typing import cast

from libcloud.compute.providers import DRIVERS, set_driver

PROVIDER_NAME = "servers"
DRIVER_MODULE = "provisioners.servers.driver"
DRIVER_CLASS = "ServersNodeDriver"


def register() -> None:
    """Register the driver with libcloud as provider "servers" (safe to call repeatedly)."""
    registered = cast(dict[str, tuple[str, str]], DRIVERS).get(PROVIDER_NAME)
    if registered is None:
        # libcloud's annotations say module/class objects; it takes (and stores) names.
        set_driver(PROVIDER_NAME, DRIVER_MODULE, DRIVER_CLASS)  # type: ignore[arg-type]
    elif tuple(registered) != (DRIVER_MODULE, DRIVER_CLASS):
        raise RuntimeError(f"libcloud provider {PROVIDER_NAME!r} is already {registered!r}")
