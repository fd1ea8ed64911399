"""What a CloudSim says about its own health (read by its master), and the worker heartbeat."""

from __future__ import annotations

import time
from importlib import metadata
from typing import Any

import redis
from celery import shared_task
from flask import current_app
from sqlalchemy import text

from cloudsim.config import Config
from cloudsim.extensions import db

HEARTBEAT_KEY = "cloudsim:worker-heartbeat"
HEARTBEAT_SECONDS = 10
WORKER_SILENT_SECONDS = 3 * HEARTBEAT_SECONDS  # no heartbeat this long: the worker is down


def _redis() -> redis.Redis:
    config: Config = current_app.config["CLOUDSIM"]
    return redis.Redis.from_url(
        config.effective_redis_url,
        decode_responses=True,
        socket_timeout=2,
        socket_connect_timeout=2,
    )


@shared_task(name="cloudsim.team_instances.heartbeat")
def heartbeat() -> None:
    """Note that a worker took a task just now (beat sends this every HEARTBEAT_SECONDS)."""
    _redis().set(HEARTBEAT_KEY, f"{time.time():.3f}", ex=3600)


def report() -> dict[str, Any]:
    """Return this CloudSim's version and whether its database, queue and worker are alive."""
    answer: dict[str, Any] = {"version": metadata.version("cloudsim")}
    try:
        db.session.execute(text("SELECT 1"))
        answer["database"] = True
    except Exception:  # reported, not raised: this is the health check
        db.session.rollback()
        answer["database"] = False
    try:
        client = _redis()
        client.ping()
        answer["queue"] = True
        seen = client.get(HEARTBEAT_KEY)
    except redis.RedisError:
        answer["queue"], seen = False, None
    age = time.time() - float(seen) if seen else None
    answer["worker"] = age is not None and age < WORKER_SILENT_SECONDS
    answer["worker_seen_seconds_ago"] = None if age is None else round(age, 1)
    return answer
