"""Provider-neutral firewall rules: who may reach the machines of one role, on what."""

import re
from dataclasses import dataclass

PROTOCOLS = ("tcp", "udp", "icmp", "all")
PORTED_PROTOCOLS = ("tcp", "udp")
SOURCE_LAN = "lan"
SOURCE_ANY = "any"
# every address outside the constellation's LAN: a security group cannot exclude the LAN, so
# there it is "any" and the host firewall (which can) leaves the LAN out
SOURCE_PUBLIC = "public"
ROLE_SOURCE_PREFIX = "role:"
MIN_PORT = 0
MAX_PORT = 65535

# Role names end up in security group names, tags, hostnames and shell commands.
_ROLE_NAME = re.compile(r"[a-z][a-z0-9_-]{0,30}\Z")


def check_role_name(field_name: str, role: object) -> str:
    """Return role if it is a valid role name, else raise ValueError naming field_name."""
    if not isinstance(role, str) or not _ROLE_NAME.match(role):
        raise ValueError(
            f"{field_name} must be a role name (lowercase letter, then up to 30 lowercase "
            f"letters, digits, '_' or '-'), got {role!r}"
        )
    return role


@dataclass(frozen=True)
class FirewallRule:
    """Allow traffic from source to the machines of to_role on protocol and ports.

    ports is an inclusive (first, last) range, None for all ports; it must be None for icmp
    and all. source is "lan" (the constellation's subnet), "any" (every address), "public"
    (every address but the LAN's) or "role:NAME" (the machines of role NAME).
    """

    to_role: str
    protocol: str
    ports: tuple[int, int] | None
    source: str

    def __post_init__(self) -> None:
        check_role_name("to_role", self.to_role)
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {PROTOCOLS}, got {self.protocol!r}")
        self._check_ports()
        self._check_source()

    @property
    def source_role(self) -> str | None:
        """Return the role named by a "role:NAME" source, else None."""
        if self.source.startswith(ROLE_SOURCE_PREFIX):
            return self.source[len(ROLE_SOURCE_PREFIX) :]
        return None

    def _check_ports(self) -> None:
        if self.ports is None:
            return
        if self.protocol not in PORTED_PROTOCOLS:
            raise ValueError(f"ports must be None for protocol {self.protocol!r}")
        if (
            not isinstance(self.ports, tuple)
            or len(self.ports) != 2
            or not all(type(port) is int for port in self.ports)
        ):
            raise ValueError(f"ports must be a (first, last) tuple of two ints, got {self.ports!r}")
        first, last = self.ports
        if not MIN_PORT <= first <= last <= MAX_PORT:
            raise ValueError(
                f"ports must satisfy {MIN_PORT} <= first <= last <= {MAX_PORT}, got {self.ports!r}"
            )

    def _check_source(self) -> None:
        if not isinstance(self.source, str):
            raise ValueError(f"source must be a string, got {self.source!r}")
        if self.source in (SOURCE_LAN, SOURCE_ANY, SOURCE_PUBLIC):
            return
        if not self.source.startswith(ROLE_SOURCE_PREFIX):
            raise ValueError(
                f"source must be {SOURCE_LAN!r}, {SOURCE_ANY!r}, {SOURCE_PUBLIC!r} or 'role:NAME', "
                f"got {self.source!r}"
            )
        check_role_name("source", self.source_role)
