"""Readiness: whether every part CloudSim needs answers, each named, with no secret in it."""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

import redis
from flask import current_app
from sqlalchemy import func, select, text

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import PortalUpload, UploadState, utcnow
from cloudsim.monitoring import heartbeats

# A worker runs the instance heartbeat task every 10 s and the beat sends it: silence this
# long means the part is down (three missed beats, so one slow task does not flap it).
SILENT_SECONDS = 30.0
WAITING = (UploadState.PENDING, UploadState.UPLOADING)


@dataclass(frozen=True)
class Check:
    """One part's state: ok or not, and a short reason a person can act on."""

    name: str
    ok: bool
    detail: str

    def as_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "detail": self.detail}


def redis_client(config: Config) -> redis.Redis:
    """Return a client of the broker's Redis with short timeouts (a check must not hang)."""
    return redis.Redis.from_url(
        config.effective_redis_url, socket_timeout=2, socket_connect_timeout=2
    )


def _database() -> Check:
    try:
        db.session.execute(text("SELECT 1"))
    except Exception as exc:  # reported, not raised: this is the health check
        db.session.rollback()
        return Check("database", False, f"unreachable ({type(exc).__name__})")
    return Check("database", True, db.engine.dialect.name)


def _heard(name: str, seen: dict[str, float] | None, prefix: str, now: float) -> Check:
    if seen is None:
        return Check(name, False, "unknown: Redis is unreachable")
    times = [at for who, at in seen.items() if who.startswith(prefix)]
    if not times:
        return Check(name, False, "never heard from")
    age = now - max(times)
    if age > SILENT_SECONDS:
        return Check(name, False, f"silent for {age:.0f} s")
    count = f"{len(times)} heard from, " if prefix == heartbeats.WORKER else ""
    return Check(name, True, f"{count}last {age:.0f} s ago")


def _disk(config: Config) -> Check:
    free_mb = shutil.disk_usage(config.instance_dir).free // 2**20
    ok = free_mb >= config.ready_min_free_mb
    return Check("disk", ok, f"{free_mb} MB free (needs {config.ready_min_free_mb})")


def _outbox(config: Config) -> Check:
    oldest = db.session.scalar(
        select(func.min(PortalUpload.created_at)).where(PortalUpload.state.in_(WAITING))
    )
    if oldest is None:
        return Check("outbox", True, "empty")
    age = (utcnow() - oldest).total_seconds()
    if age > config.ready_outbox_seconds:
        return Check("outbox", False, f"a run has waited {timedelta(seconds=int(age))} to upload")
    return Check("outbox", True, f"oldest waiting {age:.0f} s")


def checks() -> list[Check]:
    """Check the database, Redis, the workers, the beat, free disk and the portal outbox."""
    config: Config = current_app.config["CLOUDSIM"]
    found = [_database()]
    seen: dict[str, float] | None
    try:
        client = redis_client(config)
        client.ping()
        seen = heartbeats.heard(client)
        found.append(Check("redis", True, "answers"))
    except redis.RedisError as exc:
        seen = None
        found.append(Check("redis", False, f"unreachable ({type(exc).__name__})"))
    now = time.time()
    found.append(_heard("workers", seen, heartbeats.WORKER, now))
    found.append(_heard("beat", seen, heartbeats.BEAT, now))
    found.append(_disk(config))
    try:
        found.append(_outbox(config))
    except Exception as exc:  # the database check above already names the cause
        db.session.rollback()
        found.append(Check("outbox", False, f"unknown ({type(exc).__name__})"))
    return found


def readiness() -> tuple[bool, dict[str, Any]]:
    """Return whether CloudSim is ready, and the JSON body that says why (the failing parts)."""
    found = checks()
    ready = all(c.ok for c in found)
    body: dict[str, Any] = {
        "status": "ready" if ready else "not ready",
        "failing": [c.name for c in found if not c.ok],
        "checks": {c.name: c.as_dict() for c in found},
    }
    return ready, body
