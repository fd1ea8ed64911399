"""On a team instance: tell drift (a change made here by hand) from the master's news.

Each item of a desired state (a user, a task, a world, the team) is remembered by the digest
of what the master last said of it. A difference found on an item the master says the same
of as last time was made here: drift, put back and reported as such. A difference on an item
the master changed is its news. Kept in this CloudSim's Redis: if that is lost, the next sync
counts its differences as news once (they are still put back).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import redis
from flask import current_app

from cloudsim.config import Config

SEEN_KEY = "cloudsim:desired-state:seen"


def _digest(spec: Any) -> str:
    return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()


class Seen:
    """What the master said of each item at the last sync, and what it says now."""

    def __init__(self) -> None:
        config: Config = current_app.config["CLOUDSIM"]
        self._redis = redis.Redis.from_url(
            config.effective_redis_url, decode_responses=True, socket_timeout=5
        )
        self.before = {str(k): str(v) for k, v in self._redis.hgetall(SEEN_KEY).items()}
        self.now: dict[str, str] = {}

    def same(self, key: str, spec: Any) -> bool:
        """Note what the master says of `key` now; return whether it said the same last time."""
        digest = _digest(spec)
        self.now[key] = digest
        return self.before.get(key) == digest

    def listed_before(self, key: str) -> bool:
        """Return whether the master listed `key` at the last sync."""
        return key in self.before

    def save(self) -> None:
        """Remember what the master said this time (for the next sync)."""
        with self._redis.pipeline() as pipe:
            pipe.delete(SEEN_KEY)
            for key, digest in self.now.items():
                pipe.hset(SEEN_KEY, key, digest)
            pipe.execute()
