"""What a provider can still take (hosts, networks, public addresses) and what a launch asks."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Demand:
    """What a launch asks for: hosts, private networks, public addresses."""

    hosts: int = 0
    networks: int = 0
    public: int = 0
    roles: tuple[str, ...] = ()  # each host's role: what its memory counts as


@dataclass(frozen=True)
class Capacity:
    """How much more this machine can take, and what limits it."""

    hosts: int
    networks: int
    public: int
    limited_by: str
    bounds: dict[str, int] = field(default_factory=dict)  # hosts each resource allows
    memory_mib: int | None = None  # memory left for hosts; None: the provider does not count it
    memory_limited_by: str = ""
    host_memory_mib: dict[str, int] = field(default_factory=dict)  # what a role's host counts
    default_host_memory_mib: int = 0

    def memory_of(self, demand: Demand) -> int:
        """Return the MiB demand's hosts count as (0 when this provider does not count it)."""
        if self.memory_mib is None:
            return 0
        return sum(
            self.host_memory_mib.get(role, self.default_host_memory_mib) for role in demand.roles
        )

    def shortfall(self, demand: Demand) -> str | None:
        """Return why demand does not fit, or None when it does."""
        short = [
            f"{wanted} {what} (room for {room})"
            for what, wanted, room in (
                ("hosts", demand.hosts, self.hosts),
                ("private networks", demand.networks, self.networks),
                ("public addresses", demand.public, self.public),
                ("MiB of memory", self.memory_of(demand), self.memory_mib or 0),
            )
            if wanted > room
        ]
        if not short:
            return None
        memory = (
            f" and {self.memory_mib} MiB of memory (limited by {self.memory_limited_by})"
            if self.memory_of(demand) > (self.memory_mib or 0)
            else ""
        )
        return (
            f"this machine can take {self.hosts} more host(s) "
            f"(limited by {self.limited_by}){memory}; the launch needs " + ", ".join(short)
        )
