"""Per-direction counters and the cap decision (pure: no sockets, no clock)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from csrouter.packets import PacketSize


@dataclass
class Totals:
    """Packets and bytes counted in one class (accepted or dropped)."""

    packets: int = 0
    ip_bytes: int = 0
    payload_bytes: int = 0

    def add(self, size: PacketSize) -> None:
        """Count one packet."""
        self.packets += 1
        self.ip_bytes += size.ip_bytes
        self.payload_bytes += size.payload_bytes

    def as_dict(self) -> dict[str, int]:
        """Return the counts as plain JSON-able values."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Totals:
        """Rebuild counts saved by as_dict."""
        return cls(int(data["packets"]), int(data["ip_bytes"]), int(data["payload_bytes"]))


@dataclass
class DirectionMeter:
    """One direction of a run: what was accepted and dropped, and what is left of the cap.

    The cap counts TCP/UDP payload bits. A packet is accepted only while the direction is
    not spent and its whole payload fits in what is left; the first packet that does not
    fit spends the direction, and from then on every packet (even an empty ACK) is dropped
    until the next arm. Without a cap (None) everything is accepted and counted.
    """

    cap_bits: int | None = None
    accepted: Totals = field(default_factory=Totals)
    dropped: Totals = field(default_factory=Totals)
    spent: bool = False
    spent_at: str | None = None  # when the cap was spent (UTC, ISO 8601); set by the caller
    # this second's share, for the bandwidth log
    second_accepted: Totals = field(default_factory=Totals)
    second_dropped: Totals = field(default_factory=Totals)

    def __post_init__(self) -> None:
        if self.cap_bits is not None and self.cap_bits < 0:
            raise ValueError(f"a cap cannot be negative ({self.cap_bits} bits)")

    @property
    def remaining_bits(self) -> int | None:
        """Return the bits of payload still allowed, None without a cap."""
        if self.cap_bits is None:
            return None
        return self.cap_bits - 8 * self.accepted.payload_bytes

    def admit(self, size: PacketSize) -> bool:
        """Decide one packet: True = accept (and count it), False = drop (and count that)."""
        remaining = self.remaining_bits
        if remaining is not None and (self.spent or 8 * size.payload_bytes > remaining):
            self.spent = True
            self.dropped.add(size)
            self.second_dropped.add(size)
            return False
        self.accepted.add(size)
        self.second_accepted.add(size)
        return True

    def take_second(self) -> tuple[Totals, Totals]:
        """Return this second's accepted and dropped counts and start the next second."""
        taken = (self.second_accepted, self.second_dropped)
        self.second_accepted, self.second_dropped = Totals(), Totals()
        return taken

    def snapshot(self) -> dict[str, Any]:
        """Return the run's counts for this direction as JSON-able values."""
        return {
            "cap_bits": self.cap_bits,
            "remaining_bits": self.remaining_bits,
            "spent": self.spent,
            "spent_at": self.spent_at,
            "accepted": self.accepted.as_dict(),
            "dropped": self.dropped.as_dict(),
        }

    @classmethod
    def restore(cls, data: dict[str, Any]) -> DirectionMeter:
        """Rebuild a meter from a snapshot (after a daemon restart)."""
        cap = data["cap_bits"]
        return cls(
            cap_bits=None if cap is None else int(cap),
            accepted=Totals.from_dict(data["accepted"]),
            dropped=Totals.from_dict(data["dropped"]),
            spent=bool(data["spent"]),
            spent_at=data.get("spent_at"),
        )
