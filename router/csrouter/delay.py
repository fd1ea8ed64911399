"""A delay line: packets held until their deadline, then accepted, earliest first."""

from __future__ import annotations

import heapq
import itertools
from typing import Protocol


class Verdictable(Protocol):
    """What the delay line needs of a queued packet (netfilterqueue.Packet)."""

    def accept(self) -> None: ...

    def drop(self) -> None: ...


class DelayLine:
    """Held packets ordered by release time (FIFO for one latency; a re-arm may change it)."""

    def __init__(self) -> None:
        self._held: list[tuple[float, int, Verdictable]] = []
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, packet: Verdictable, release_at: float) -> None:
        """Keep a packet until release_at (monotonic seconds)."""
        heapq.heappush(self._held, (release_at, next(self._order), packet))

    def release_due(self, now: float) -> int:
        """Accept every packet whose time has come; return how many."""
        released = 0
        while self._held and self._held[0][0] <= now:
            heapq.heappop(self._held)[2].accept()
            released += 1
        return released

    def next_release(self) -> float | None:
        """Return when the next packet is due, None when nothing is held."""
        return self._held[0][0] if self._held else None
