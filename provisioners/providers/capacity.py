"""What a provider can still take (hosts, networks, public addresses) and what a launch asks."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Demand:
    """What a launch asks for: hosts, private networks, public addresses."""

    hosts: int = 0
    networks: int = 0
    public: int = 0


@dataclass(frozen=True)
class Capacity:
    """How much more this machine can take, and what limits it."""

    hosts: int
    networks: int
    public: int
    limited_by: str
    bounds: dict[str, int] = field(default_factory=dict)  # hosts each resource allows

    def shortfall(self, demand: Demand) -> str | None:
        """Return why demand does not fit, or None when it does."""
        short = [
            f"{wanted} {what} (room for {room})"
            for what, wanted, room in (
                ("hosts", demand.hosts, self.hosts),
                ("private networks", demand.networks, self.networks),
                ("public addresses", demand.public, self.public),
            )
            if wanted > room
        ]
        if not short:
            return None
        return (
            f"this machine can take {self.hosts} more host(s) "
            f"(limited by {self.limited_by}); the launch needs " + ", ".join(short)
        )
