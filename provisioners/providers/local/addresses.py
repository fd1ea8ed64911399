"""Pure address arithmetic: subnets from a pool, host addresses inside a subnet, names."""

import re
from collections.abc import Iterable
from ipaddress import IPv4Address, IPv4Network, ip_address, ip_network

from provisioners.providers.local.errors import AddressError, InvalidRequestError

# A subnet needs room for a reserved gateway address and at least two hosts.
MAX_PREFIXLEN = 29

# Hostname-like, so a node name can be a hostname, part of a netns name and a machine name.
_NAME_PATTERN = re.compile(r"^[a-z0-9]([a-z0-9-]*[a-z0-9])?$")
_PREFIX_PATTERN = re.compile(r"^[a-z][a-z0-9]{0,11}$")
MAX_NAME_LENGTH = 40


def parse_subnet(cidr: str, max_prefixlen: int = MAX_PREFIXLEN) -> IPv4Network:
    """Parse an IPv4 subnet in CIDR notation, refusing host bits and too small subnets."""
    try:
        subnet = ip_network(cidr, strict=True)
    except ValueError as error:
        raise InvalidRequestError(
            f"{cidr!r} is not an IPv4 subnet in CIDR notation: {error}"
        ) from error
    if not isinstance(subnet, IPv4Network):
        raise InvalidRequestError(f"{cidr!r} is not an IPv4 subnet")
    if subnet.prefixlen > max_prefixlen:
        raise InvalidRequestError(f"{cidr!r} is too small (at most /{max_prefixlen})")
    return subnet


def parse_address(text: str) -> IPv4Address:
    """Parse one IPv4 address."""
    try:
        address = ip_address(text)
    except ValueError as error:
        raise InvalidRequestError(f"{text!r} is not an IPv4 address: {error}") from error
    if not isinstance(address, IPv4Address):
        raise InvalidRequestError(f"{text!r} is not an IPv4 address")
    return address


def allocate_subnet(
    pool: IPv4Network, taken: Iterable[IPv4Network], prefixlen: int = 24
) -> IPv4Network:
    """Return the first /prefixlen of pool that overlaps none of the taken subnets."""
    if prefixlen < pool.prefixlen:
        raise AddressError(f"the pool {pool} is smaller than one /{prefixlen}")
    taken_subnets = list(taken)
    for candidate in pool.subnets(new_prefix=prefixlen):
        if not any(candidate.overlaps(other) for other in taken_subnets):
            return candidate
    raise AddressError(f"no free /{prefixlen} left in the subnet pool {pool}")


def count_free_subnets(pool: IPv4Network, prefix: int, taken: Iterable[IPv4Network]) -> int:
    """Count the pool's subnets of this prefix that overlap none of taken."""
    # By index arithmetic: the constellations page and capacity API ask at every view, and
    # testing each of a /16's 256 candidates against every taken network cost ~1.5 ms.
    if prefix < pool.prefixlen:
        return 0
    shift = 32 - prefix
    start, last = int(pool.network_address), int(pool.broadcast_address)
    used: set[int] = set()
    for network in taken:
        low = max(int(network.network_address), start)
        high = min(int(network.broadcast_address), last)
        if low <= high:
            used.update(range((low - start) >> shift, ((high - start) >> shift) + 1))
    return ((last - start + 1) >> shift) - len(used)


def check_subnet_free(subnet: IPv4Network, taken: Iterable[IPv4Network]) -> None:
    """Raise AddressError when subnet overlaps a subnet already in use."""
    for other in taken:
        if subnet.overlaps(other):
            raise AddressError(f"subnet {subnet} overlaps {other}, which is already in use")


def gateway_address(subnet: IPv4Network) -> IPv4Address:
    """Return the subnet's first usable address, kept free for a gateway."""
    return subnet.network_address + 1


def allocate_address(subnet: IPv4Network, taken: Iterable[IPv4Address]) -> IPv4Address:
    """Return the lowest free host address of subnet, skipping the gateway address."""
    used = set(taken) | {gateway_address(subnet)}
    for candidate in subnet.hosts():
        if candidate not in used:
            return candidate
    raise AddressError(f"no free address left in {subnet}")


def check_address_free(
    subnet: IPv4Network, address: IPv4Address, taken: Iterable[IPv4Address]
) -> None:
    """Raise unless address is a host address of subnet that nobody uses yet."""
    if address not in subnet or address in (subnet.network_address, subnet.broadcast_address):
        raise AddressError(f"{address} is not a host address of {subnet}")
    if address in set(taken):
        raise AddressError(f"{address} is already used on {subnet}")


def interface_cidr(address: IPv4Address, subnet: IPv4Network) -> str:
    """Return address/prefixlen, the form `ip addr add` takes."""
    return f"{address}/{subnet.prefixlen}"


def check_name(kind: str, name: str) -> str:
    """Return name if it can serve as a hostname and inside netns names, else raise."""
    if len(name) > MAX_NAME_LENGTH or not _NAME_PATTERN.fullmatch(name):
        raise InvalidRequestError(
            f"invalid {kind} name {name!r}: use 1-{MAX_NAME_LENGTH} characters among "
            "a-z, 0-9 and '-', not starting or ending with '-'"
        )
    return name


def check_prefix(prefix: str) -> str:
    """Return prefix if it is a short lowercase word, else raise."""
    if not _PREFIX_PATTERN.fullmatch(prefix):
        raise InvalidRequestError(
            f"invalid prefix {prefix!r}: 1-12 characters a-z and 0-9, starting with a letter"
        )
    return prefix
