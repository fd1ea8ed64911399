"""A delay line: packets held until their deadline, then accepted, earliest first."""

from __future__ import annotations

import heapq
import itertools
from typing import Protocol


class Verdictable(Protocol):
    """What the delay line needs of a queued packet (netfilterqueue.Packet)."""

    def accept(self) -> None: ...

    def drop(self) -> None: ...


class Lateness:
    """How late packets left compared with their release time (csrouter's own timing error)."""

    def __init__(self) -> None:
        self.packets = 0
        self.total_s = 0.0
        self.max_s = 0.0

    def add(self, late_s: float) -> None:
        """Record one released packet."""
        self.packets += 1
        self.total_s += late_s
        self.max_s = max(self.max_s, late_s)

    def as_dict(self) -> dict[str, float]:
        """Return mean and max in milliseconds over the packets recorded."""
        mean = self.total_s / self.packets if self.packets else 0.0
        return {
            "packets": self.packets,
            "mean_ms": round(mean * 1000, 3),
            "max_ms": round(self.max_s * 1000, 3),
        }


class DelayLine:
    """Held packets ordered by release time (FIFO for one latency; a re-arm may change it)."""

    def __init__(self) -> None:
        self._held: list[tuple[float, int, Verdictable]] = []
        self._order = itertools.count()
        self.lateness = Lateness()

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, packet: Verdictable, release_at: float) -> None:
        """Keep a packet until release_at (monotonic seconds)."""
        heapq.heappush(self._held, (release_at, next(self._order), packet))

    def release_due(self, now: float) -> int:
        """Accept every packet whose time has come; return how many."""
        released = 0
        while self._held and self._held[0][0] <= now:
            release_at, _, packet = heapq.heappop(self._held)
            packet.accept()
            self.lateness.add(now - release_at)
            released += 1
        return released

    def next_release(self) -> float | None:
        """Return when the next packet is due, None when nothing is held."""
        return self._held[0][0] if self._held else None
