"""Network namespaces, bridges and veth pairs, built with `ip` and never in the root namespace."""

from pathlib import Path

from provisioners.providers.local.commands import command_succeeds, run_command
from provisioners.providers.local.errors import CommandError

NETNS_DIR = Path("/run/netns")
BRIDGE_NAME = "br0"


def netns_path(name: str) -> Path:
    """Return the bind-mounted file that names network namespace `name`."""
    return NETNS_DIR / name


def namespace_exists(name: str) -> bool:
    """Say whether network namespace `name` exists."""
    return netns_path(name).exists()


def list_namespaces(prefix: str) -> list[str]:
    """Return the names of the network namespaces starting with `prefix`."""
    if not NETNS_DIR.is_dir():
        return []
    return sorted(entry.name for entry in NETNS_DIR.iterdir() if entry.name.startswith(prefix))


def create_namespace(name: str) -> None:
    """Create network namespace `name` with loopback up and IPv6 off."""
    run_command(["ip", "netns", "add", name])
    # IPv6 off keeps link-local chatter out of byte counters measured later on the LAN.
    run_command(
        [
            "ip", "netns", "exec", name, "sysctl", "-qw",
            "net.ipv6.conf.all.disable_ipv6=1", "net.ipv6.conf.default.disable_ipv6=1",
        ]
    )  # fmt: skip
    run_command(["ip", "-n", name, "link", "set", "lo", "up"])


def delete_namespace(name: str) -> None:
    """Delete network namespace `name` (its interfaces go with it); no-op when absent."""
    if not namespace_exists(name):
        return
    try:
        run_command(["ip", "netns", "delete", name])
    except CommandError:
        # Another destroy of the same thing may have deleted it a moment ago: that is success.
        if namespace_exists(name):
            raise


def create_bridge(namespace: str, address_cidr: str | None = None) -> None:
    """Create the bridge of a switch namespace, optionally giving it an address."""
    run_command(["ip", "-n", namespace, "link", "add", BRIDGE_NAME, "type", "bridge"])
    if address_cidr is not None:
        run_command(["ip", "-n", namespace, "addr", "add", address_cidr, "dev", BRIDGE_NAME])
    run_command(["ip", "-n", namespace, "link", "set", BRIDGE_NAME, "up"])


def plug_into_switch(
    host_namespace: str, interface: str, switch_namespace: str, port: str, address_cidr: str
) -> None:
    """Link host_namespace:interface to the switch bridge through a veth pair and address it."""
    run_command(
        [
            "ip", "link", "add", interface, "netns", host_namespace,
            "type", "veth", "peer", "name", port, "netns", switch_namespace,
        ]
    )  # fmt: skip
    run_command(["ip", "-n", switch_namespace, "link", "set", port, "master", BRIDGE_NAME, "up"])
    run_command(["ip", "-n", host_namespace, "addr", "add", address_cidr, "dev", interface])
    run_command(["ip", "-n", host_namespace, "link", "set", interface, "up"])


def add_default_route(namespace: str, via: str) -> None:
    """Route everything not on a local subnet through `via`."""
    run_command(["ip", "-n", namespace, "route", "add", "default", "via", via])


def namespace_pids(name: str) -> list[int]:
    """Return the PIDs of every process living in network namespace `name`."""
    if not namespace_exists(name):
        return []
    try:
        output = run_command(["ip", "netns", "pids", name])
    except CommandError:
        if namespace_exists(name):
            raise
        return []  # deleted meanwhile (a concurrent destroy): it holds no process any more
    return [int(line) for line in output.split()]


def can_connect(namespace: str, address: str, port: int, timeout: float = 2.0) -> bool:
    """Say whether a TCP connection to address:port succeeds from inside `namespace`."""
    probe = 'exec 3<>"/dev/tcp/$1/$2"'
    argv = ["nsenter", f"--net={netns_path(namespace)}", "bash", "-c", probe, "probe"]
    return command_succeeds([*argv, address, str(int(port))], timeout=timeout)


def connect_command(namespace: str, address: str, port: int) -> list[str]:
    """Return an argv piping stdio to address:port from inside `namespace` (a ProxyCommand)."""
    return [
        "nsenter",
        f"--net={netns_path(namespace)}",
        "socat",
        "STDIO",
        f"TCP:{address}:{int(port)}",
    ]
