"""Who was heard from when: each worker (by host name) and the beat, in one Redis hash.

A worker records itself after every task it runs (beat sends the instance heartbeat task
every 10 s, so an idle worker is heard from too); the beat records itself whenever it sends a
task. Both use the broker's Redis, so they need no app context and no database.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import redis
from celery import Task
from celery.signals import after_task_publish, beat_init, task_postrun

log = logging.getLogger(__name__)
KEY = "cloudsim:heard-from"
BEAT = "beat"
WORKER = "worker:"
_clients: dict[str, redis.Redis] = {}
_in_beat = False


def _client(url: str) -> redis.Redis:
    """Return this process's client for url (one per process: workers fork)."""
    if url not in _clients:
        _clients[url] = redis.Redis.from_url(url, socket_timeout=2, socket_connect_timeout=2)
    return _clients[url]


def note(url: str, who: str, at: float | None = None) -> None:
    """Record that `who` was heard from now (a failure is logged: it must not fail a task)."""
    try:
        _client(url).hset(KEY, who, f"{time.time() if at is None else at:.3f}")
    except redis.RedisError as exc:
        log.warning("could not record the heartbeat of %s: %s", who, exc)


def heard(client: redis.Redis) -> dict[str, float]:
    """Return when each worker and the beat were last heard from (UNIX seconds)."""
    raw: dict[Any, Any] = client.hgetall(KEY)  # type: ignore[assignment]
    found = {}
    for who, when in raw.items():
        name = who.decode() if isinstance(who, bytes) else str(who)
        try:
            found[name] = float(when)
        except ValueError:
            continue
    return found


@beat_init.connect
def _beat_started(sender: Any = None, **_: Any) -> None:
    global _in_beat
    _in_beat = True
    note(sender.app.conf.broker_url, BEAT)


@after_task_publish.connect
def _beat_sent(sender: Any = None, **_: Any) -> None:
    # Every process publishes (the web app queues jobs): only the beat's sends are its pulse.
    if _in_beat:
        from celery import current_app

        note(current_app.conf.broker_url, BEAT)


@task_postrun.connect
def _worker_ran(sender: Task | None = None, **_: Any) -> None:
    if sender is None:
        return
    hostname = getattr(sender.request, "hostname", None)
    if not hostname:  # run in-process (eagerly), not by a worker
        return
    note(sender.app.conf.broker_url, WORKER + hostname)
