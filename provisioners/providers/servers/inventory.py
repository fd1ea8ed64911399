"""The inventory: existing servers, how to log in to them and which pre-made LAN each is on."""

from __future__ import annotations

import ipaddress
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from provisioners.providers.servers.errors import InventoryError
from provisioners.remote.ssh import SSHError, load_private_key

DEFAULT_USER = "root"
DEFAULT_PORT = 22
# A server's name is also the hostname it gets back on release.
_HOSTNAME = re.compile(r"^[a-z0-9]([a-z0-9-]{0,61}[a-z0-9])?$")
_WORD = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,62}$")
_USER = re.compile(r"^[a-z_][a-z0-9_-]{0,31}$")
_HOST_KEY = re.compile(r"^(ssh-|ecdsa-)[a-z0-9-]+ [A-Za-z0-9+/]+={0,2}$")
REQUIRED_FIELDS = ("name", "address", "private_ip", "network", "cidr", "private_key")
OPTIONAL_FIELDS = ("port", "public_ip", "user", "host_key", "proxy_command", "capabilities")


@dataclass(frozen=True, kw_only=True)
class Server:
    """One existing machine CloudSim may claim."""

    name: str
    address: str
    private_ip: str
    network: str
    cidr: str
    private_key: str = field(repr=False)
    login_key_blob: str = field(repr=False)  # base64 of the login key's public half
    port: int = DEFAULT_PORT
    public_ip: str | None = None
    user: str = DEFAULT_USER
    host_key: str | None = None
    proxy_command: tuple[str, ...] | None = None
    capabilities: frozenset[str] = frozenset()


class Inventory:
    """Validated servers, in the order given; a malformed entry is refused naming its field."""

    def __init__(self, entries: Sequence[Mapping[str, Any]]) -> None:
        if isinstance(entries, (str, bytes)) or not isinstance(entries, Sequence):
            raise InventoryError("the inventory must be a list of servers")
        if not entries:
            raise InventoryError("the inventory lists no servers")
        self.servers: tuple[Server, ...] = tuple(
            _parse_entry(index, entry) for index, entry in enumerate(entries, start=1)
        )
        _check_unique(self.servers)

    @classmethod
    def of(cls, inventory: Inventory | Sequence[Mapping[str, Any]]) -> Inventory:
        """Return inventory itself, or the Inventory its entries make."""
        return inventory if isinstance(inventory, Inventory) else cls(inventory)

    def server(self, name: str) -> Server | None:
        """Return the named server, None when the inventory has none of that name."""
        return next((server for server in self.servers if server.name == name), None)

    def networks(self) -> dict[str, str]:
        """Return each pre-made LAN's name and CIDR, in inventory order."""
        return {server.network: server.cidr for server in self.servers}

    def in_network(self, network: str) -> list[Server]:
        """Return the servers on one pre-made LAN."""
        return [server for server in self.servers if server.network == network]


def _parse_entry(index: int, entry: Mapping[str, Any]) -> Server:
    if not isinstance(entry, Mapping):
        raise InventoryError(f"inventory entry {index} must be a mapping of fields")
    raw_name = entry.get("name")
    label = f"inventory entry {index}" + (f" ({raw_name!r})" if isinstance(raw_name, str) else "")

    def fail(field_name: str, problem: str) -> InventoryError:
        return InventoryError(f"{label}: field {field_name!r} {problem}")

    unknown = sorted(set(entry) - set(REQUIRED_FIELDS) - set(OPTIONAL_FIELDS))
    if unknown:
        raise fail(unknown[0], f"is not a server field (known: {', '.join(_all_fields())})")
    for name in REQUIRED_FIELDS:
        if entry.get(name) in (None, ""):
            raise fail(name, "is required")
    for name in ("name", "address", "private_ip", "network", "cidr", "private_key", "user"):
        if name in entry and not isinstance(entry[name], str):
            raise fail(name, "must be a string")
    name = entry["name"]
    if not _HOSTNAME.match(name):
        raise fail("name", "must be a hostname: a-z, 0-9 and '-', at most 63 characters")
    address = entry["address"].strip()
    if not address or any(char.isspace() for char in address):
        raise fail("address", "must be a host name or IP address")
    try:
        cidr = ipaddress.IPv4Network(entry["cidr"], strict=True)
    except ValueError as error:
        raise fail("cidr", f"is not an IPv4 network ({error})") from error
    private_ip = _address(entry["private_ip"], lambda problem: fail("private_ip", problem))
    if private_ip not in cidr or private_ip in (cidr.network_address, cidr.broadcast_address):
        raise fail("private_ip", f"{private_ip} is not a host address of cidr {cidr}")
    public_ip = entry.get("public_ip")
    if public_ip is not None:
        public_ip = str(_address(public_ip, lambda problem: fail("public_ip", problem)))
    network = entry["network"]
    if not _WORD.match(network):
        raise fail("network", "must be a word of letters, digits, '_', '.' and '-'")
    user = entry.get("user", DEFAULT_USER)
    if not isinstance(user, str) or not _USER.match(user):
        raise fail("user", "must be a Unix user name")
    port = entry.get("port", DEFAULT_PORT)
    if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
        raise fail("port", "must be a TCP port number")
    host_key = entry.get("host_key")
    if host_key is not None and (not isinstance(host_key, str) or not _HOST_KEY.match(host_key)):
        raise fail("host_key", "must be 'key-type base64' (as in known_hosts, without the host)")
    try:
        login_key = load_private_key(name, entry["private_key"])
    except SSHError as error:
        # The message never quotes the key: it is a secret.
        raise fail("private_key", "is not an unencrypted OpenSSH or PEM private key") from error
    return Server(
        name=name,
        address=address,
        port=port,
        private_ip=str(private_ip),
        public_ip=public_ip,
        network=network,
        cidr=str(cidr),
        user=user,
        private_key=entry["private_key"],
        login_key_blob=login_key.get_base64(),
        host_key=host_key,
        proxy_command=_proxy_command(entry.get("proxy_command"), fail),
        capabilities=_capabilities(entry.get("capabilities"), fail),
    )


def _all_fields() -> list[str]:
    return [*REQUIRED_FIELDS, *OPTIONAL_FIELDS]


def _address(value: Any, fail: Callable[[str], InventoryError]) -> ipaddress.IPv4Address:
    if not isinstance(value, str):
        raise fail("must be a string")
    try:
        return ipaddress.IPv4Address(value)
    except ValueError as error:
        raise fail(f"is not an IPv4 address ({error})") from error


def _proxy_command(
    value: Any, fail: Callable[[str, str], InventoryError]
) -> tuple[str, ...] | None:
    if value is None:
        return None
    if (
        isinstance(value, str)
        or not isinstance(value, Sequence)
        or not value
        or not all(isinstance(word, str) and word for word in value)
    ):
        raise fail("proxy_command", "must be a non-empty list of argv words")
    return tuple(value)


def _capabilities(value: Any, fail: Callable[[str, str], InventoryError]) -> frozenset[str]:
    if value is None:
        return frozenset()
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise fail("capabilities", "must be a list of words such as ['gpu']")
    for word in value:
        if not isinstance(word, str) or not _WORD.match(word):
            raise fail("capabilities", f"holds {word!r}, not a word such as 'gpu'")
    return frozenset(value)


def _check_unique(servers: Sequence[Server]) -> None:
    seen_names: set[str] = set()
    cidrs: dict[str, str] = {}
    lan_addresses: set[tuple[str, str]] = set()
    public_addresses: set[str] = set()
    for index, server in enumerate(servers, start=1):
        label = f"inventory entry {index} ({server.name!r})"
        if server.name in seen_names:
            raise InventoryError(f"{label}: field 'name' repeats an earlier server's name")
        seen_names.add(server.name)
        known_cidr = cidrs.setdefault(server.network, server.cidr)
        if known_cidr != server.cidr:
            raise InventoryError(
                f"{label}: field 'cidr' {server.cidr} differs from {known_cidr}, given "
                f"earlier for network {server.network!r}"
            )
        if (server.network, server.private_ip) in lan_addresses:
            raise InventoryError(f"{label}: field 'private_ip' {server.private_ip} is taken")
        lan_addresses.add((server.network, server.private_ip))
        if server.public_ip is not None:
            if server.public_ip in public_addresses:
                raise InventoryError(f"{label}: field 'public_ip' {server.public_ip} is taken")
            public_addresses.add(server.public_ip)
