"""The command port's budget per peer: a token bucket, one log line per burst of excess."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

log = logging.getLogger("drcsim.server")

RATE_PER_S = 1000.0  # sustained commands per second from one address (a 1 kHz control loop)
BURST = 500  # commands it may send at once above that
QUIET_S = 1.0  # a burst is over when the address has kept within its budget this long


@dataclass
class _Bucket:
    tokens: float
    at: float
    dropped: int = 0  # in the current burst
    burst_from: float | None = None
    last_drop: float = 0.0


@dataclass
class RateLimiter:
    """Admit at most RATE_PER_S commands a second (BURST at once) from each peer address."""

    rate: float = RATE_PER_S
    burst: int = BURST
    dropped: int = 0  # over the run, every peer
    bursts: int = 0
    buckets: dict[str, _Bucket] = field(default_factory=dict)

    def admit(self, peer: str, now: float) -> bool:
        """Return whether a command from `peer` at `now` (s, monotonic) is within budget."""
        bucket = self.buckets.get(peer)
        if bucket is None:
            bucket = self.buckets[peer] = _Bucket(float(self.burst), now)
        bucket.tokens = min(float(self.burst), bucket.tokens + (now - bucket.at) * self.rate)
        bucket.at = now
        if bucket.tokens >= 1.0:
            bucket.tokens -= 1.0
            return True
        if bucket.burst_from is None:
            bucket.burst_from = now
            self.bursts += 1
        bucket.dropped += 1
        bucket.last_drop = now
        self.dropped += 1
        return False

    def flooding(self, peer: str) -> bool:
        """Return whether `peer` is in a burst now (its messages are not logged one by one)."""
        bucket = self.buckets.get(peer)
        return bucket is not None and bucket.burst_from is not None

    def settle(self, now: float, final: bool = False) -> None:
        """Log one line for each burst that is over (every burst still going if `final`)."""
        for peer, bucket in self.buckets.items():
            if bucket.burst_from is None or (not final and now - bucket.last_drop < QUIET_S):
                continue
            log.warning(
                "rate-limited %s: dropped %d commands over %.1f s (budget %g/s, bursts of %d)",
                peer,
                bucket.dropped,
                bucket.last_drop - bucket.burst_from,
                self.rate,
                self.burst,
            )
            bucket.burst_from, bucket.dropped = None, 0
