"""Live 3D view of a running run: one relay per run, any number of (capped, throttled) viewers.

The relay is a job: over SSH it runs `drcsim watch` on the run's sim machine, which follows the
simulator's `poses` topic on that machine's loopback (ground truth is never published to the
LAN, where team code runs) and prints frames; the job keeps the newest few seconds in Redis.
Viewers poll CloudSim for them, so the simulator machine is never exposed to a browser and its
pose topic has one subscriber however many people watch.
"""

from __future__ import annotations

import json
import logging
import shlex
import time
from typing import Any

import redis
from drcsim.client import DEFAULT_COMMAND_PORT
from flask import current_app

from cloudsim.competition.jobs import DRCSIM, machines
from cloudsim.competition.lifecycle import RunJob
from cloudsim.config import Config
from cloudsim.errors import CloudSimError, Unavailable
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, job_kind
from cloudsim.jobs.service import enqueue
from cloudsim.models import Run, RunState, User
from cloudsim.viewer.service import live_run_for
from provisioners.remote.ssh import SSHError, SSHExecutor, SSHTarget

log = logging.getLogger(__name__)
BUFFER_SECONDS = 10  # of simulated time kept for viewers
VIEWER_TTL_S = 15  # a viewer that has not polled this long no longer counts
RELAY_LEASE_S = 20  # a relay that has not renewed this long is presumed dead
WATCH_CHUNK_S = 120  # one `drcsim watch` call; the relay starts another while viewers remain
CHECK_EVERY_S = 1.0
RETRY_AFTER_FAILURE_S = 30


class TooManyRequests(CloudSimError):
    """The viewer asks faster than CLOUDSIM_VIEWER_POLL_MS allows."""

    status = 429


class _RelayDone(Exception):
    """Nobody watches any more, or the run has ended: stop following the simulator."""


def _key(run_id: int, what: str) -> str:
    return f"cloudsim:viewer:run:{run_id}:{what}"


def redis_client() -> redis.Redis:
    """Return this app's Redis connection for the viewer's buffers."""
    client = current_app.extensions.get("cloudsim.viewer.redis")
    if client is None:
        config: Config = current_app.config["CLOUDSIM"]
        client = redis.Redis.from_url(config.effective_redis_url, decode_responses=True)
        current_app.extensions["cloudsim.viewer.redis"] = client
    return client


def admit(client: redis.Redis, actor: User, run: Run, viewer: str, config: Config) -> str:
    """Return the viewer's name in the count; raise when it polls too fast or is one too many."""
    member = f"{actor.id}:{viewer[:64]}"
    viewers = _key(run.id, "viewers")
    # one round trip: the throttle's mark and the viewer count (the prune is harmless if refused)
    pipe = client.pipeline()
    pipe.set(_key(run.id, f"poll:{member}"), 1, nx=True, px=config.viewer_poll_ms)
    pipe.zremrangebyscore(viewers, 0, time.time() - VIEWER_TTL_S)
    pipe.zscore(viewers, member)
    pipe.zcard(viewers)
    fresh, _, known, count = pipe.execute()
    if not fresh:
        raise TooManyRequests(f"at most one request per {config.viewer_poll_ms} ms")
    if known is None and count >= config.viewer_max_live:
        raise Unavailable(
            f"run {run.id} already has {count} live viewers (the most allowed); try later"
        )
    return member


def live_frames(
    client: redis.Redis, run: Run, member: str, after: float
) -> tuple[list[str], list[dict[str, Any]], str, bool]:
    """Count the admitted viewer and return the buffered frames newer than `after` (simulated
    seconds, as JSON texts), the score events, the relay's state and whether it must start."""
    viewers = _key(run.id, "viewers")
    pipe = client.pipeline()
    pipe.zadd(viewers, {member: time.time()})
    pipe.expire(viewers, VIEWER_TTL_S * 4)
    # one relay per run, whoever asks: the first poll without a live relay starts it
    pipe.set(_key(run.id, "relay"), "starting", nx=True, ex=RELAY_LEASE_S * 3)
    pipe.zrangebyscore(_key(run.id, "frames"), f"({after}", "+inf")
    pipe.lrange(_key(run.id, "events"), 0, -1)
    pipe.get(_key(run.id, "relay"))
    _, _, start, frames, events, relay = pipe.execute()
    return frames, [json.loads(item) for item in events], relay or "stopped", bool(start)


def store_frame(client: redis.Redis, run_id: int, frame: dict[str, Any], keep: int) -> None:
    """Add a frame to the run's live buffer (sorted by simulated time), keeping the newest."""
    key = _key(run_id, "frames")
    pipe = client.pipeline()
    pipe.zadd(key, {json.dumps(frame, separators=(",", ":")): frame["t"]})
    pipe.zremrangebyrank(key, 0, -keep - 1)
    pipe.expire(key, RELAY_LEASE_S * 3)
    pipe.execute()


def live_answer(actor: User, run_id: int, after: float, viewer: str, config: Config) -> str:
    """Return (as JSON text) the live frames newer than `after` for one admitted viewer."""
    run = live_run_for(actor, run_id)
    client = redis_client()
    try:
        member = admit(client, actor, run, viewer, config)
        frames, events, relay, start = live_frames(client, run, member, after)
    except redis.RedisError as exc:
        raise Unavailable(f"the live view needs Redis: {exc}") from exc
    if start:
        enqueue("viewer.relay", actor, RunJob(run.id), team_id=run.team_id)
    head = json.dumps(
        {
            "events": events,
            "relay": relay,
            "score": run.score,
            "falls": run.falls,
            "state": run.state.value,
        }
    )
    # the frames are passed on as the relay stored them: no parsing per viewer and poll
    return head[:-1] + ', "frames": [' + ",".join(frames) + "]}"


class _Relay:
    """Receives `drcsim watch` output lines and keeps the newest frames in Redis."""

    def __init__(self, run: Run, client: redis.Redis, config: Config) -> None:
        self.run_id = run.id
        self.client = client
        self.hz = config.viewer_live_hz
        self.keep = BUFFER_SECONDS * self.hz
        self.checked = 0.0
        self.frames = 0

    def line(self, _machine: str, line: str) -> None:
        """Take one output line of the watcher; raise _RelayDone when it should stop."""
        if line.startswith('{"frame"'):
            frame = json.loads(line)["frame"]
            store_frame(self.client, self.run_id, frame, self.keep)
            self.frames += 1
        elif line.startswith('{"score"'):
            self.client.rpush(_key(self.run_id, "events"), json.dumps(json.loads(line)["score"]))
            self.client.expire(_key(self.run_id, "events"), 3600)
        if time.monotonic() - self.checked >= CHECK_EVERY_S:
            self.checked = time.monotonic()
            self.check()

    def check(self) -> None:
        """Renew the relay's lease; raise _RelayDone when nobody watches or the run is over."""
        self.client.set(_key(self.run_id, "relay"), "running", ex=RELAY_LEASE_S)
        viewers = self.client.zcount(
            _key(self.run_id, "viewers"), time.time() - VIEWER_TTL_S, "+inf"
        )
        db.session.expire_all()
        run = db.session.get(Run, self.run_id)
        if viewers == 0 or run is None or run.state != RunState.RUNNING:
            raise _RelayDone


def follow_simulator(
    executor: SSHExecutor,
    sim: SSHTarget,
    relay: _Relay,
    *,
    drcsim: str = DRCSIM,
    port: int = DEFAULT_COMMAND_PORT,  # the run's simulator serves on drcsim's default
    chunk_s: int = WATCH_CHUNK_S,
) -> None:
    """Run `drcsim watch` on the sim machine, chunk after chunk, until the relay stops.

    The executor's log sink must be `relay.line`: it gets the watcher's output line by line
    as it arrives.
    """
    # `drcsim watch` reads the simulator's loopback-only topics port, derived from `port`
    command = f"{shlex.quote(drcsim)} watch --port {port} --rate {relay.hz} --seconds {chunk_s}"
    try:
        while True:
            relay.check()
            try:
                executor.run(sim, command, timeout=chunk_s + 30)
            except SSHError:
                relay.check()  # the run ended under the watcher: that is no failure
                raise
    except _RelayDone:
        return


@job_kind("viewer.relay", payload=RunJob)
def relay_job(ctx: JobContext, job: RunJob) -> None:
    """Follow a running run's poses on its sim machine while anybody watches it live."""
    run = ctx.load(Run, job.run_id)
    config: Config = current_app.config["CLOUDSIM"]
    client = redis_client()
    relay = _Relay(run, client, config)
    ctx.stage("relay", 50)
    try:
        with machines(run, config, sink=relay.line) as reach:
            follow_simulator(reach.executor, reach.sim, relay)
    except Exception:
        # viewers keep asking: the next relay starts after a pause, not at every poll
        client.set(_key(run.id, "relay"), "failed", ex=RETRY_AFTER_FAILURE_S)
        raise
    client.delete(_key(run.id, "relay"))
    ctx.log(f"relayed {relay.frames} frame(s) of run {run.id}; nobody watches any more")
