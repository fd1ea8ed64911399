"""A live run's figures, read once a second from its machines over CloudSim's own SSH path.

The beat sends `cloudsim.competition.live` every CLOUDSIM_RUN_LIVE_SECONDS: one worker asks
each running run's sim (its live figures and score log), router (its counters) and, every few
seconds, field computers (that they answer), over the connections the worker keeps open, and
writes what came back to Redis. Pages, the API and `cloudsim run watch` read Redis, so a page
polling every second opens no SSH connection and touches no machine. Nothing here goes through
the team's metered link: CloudSim reaches the machines on their management addresses.
"""

from __future__ import annotations

import json
import logging
import os
import shlex
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import redis
from celery import shared_task
from csrouter.protocol import payload_bits_used, spent_at
from drcsim.rundir import LIVE, SCORE, read_live, read_score_log
from flask import current_app
from sqlalchemy import select

from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.jobs import RunTargets, run_targets
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.launched_constellations import router_control
from cloudsim.models import Run, RunState
from provisioners.remote.ssh import (
    CommandFailed,
    ConnectionCache,
    ConnectPolicy,
    SSHError,
    SSHExecutor,
    SSHTarget,
    process_cache,
)

log = logging.getLogger(__name__)
KEY = "cloudsim:run-live:{}"
SAMPLES_KEY = "cloudsim:run-live:{}:bandwidth"
HEARD_KEY = "cloudsim:machine-heard:{}"  # a constellation's machines: name -> last answer
KEPT_SECONDS = 6 * 3600  # a run's live figures outlive it long enough for its page to settle
FC_EVERY_S = 5.0  # field computers are only asked whether they answer: less often
COMMAND_SECONDS = 10
REACH = ConnectPolicy(deadline=10.0, attempt_timeout=5.0)


@dataclass(frozen=True)
class Answer:
    """One machine's answer: who, when, and what it said (None: it only answered)."""

    role: str
    at: float
    figures: dict[str, Any] | None
    machine: str = ""


def connection(config: Config) -> redis.Redis:
    """Return a client of the Redis the live figures are kept in."""
    return redis.Redis.from_url(
        config.effective_redis_url,
        decode_responses=True,
        socket_timeout=2,
        socket_connect_timeout=2,
    )


def read(client: redis.Redis, run_id: int) -> tuple[dict[str, Any], int]:
    """Return a run's live figures and how many bandwidth samples it has ({} and 0: none)."""
    pipe = client.pipeline()
    pipe.get(KEY.format(run_id))
    pipe.llen(SAMPLES_KEY.format(run_id))
    figures, count = pipe.execute()
    return (json.loads(figures) if figures else {}), int(count)


def samples(client: redis.Redis, run_id: int) -> list[list[float]]:
    """Return a run's bandwidth samples: [seconds since it started running, up, down] each."""
    return [json.loads(s) for s in client.lrange(SAMPLES_KEY.format(run_id), 0, -1)]


@dataclass(frozen=True)
class LiveRun:
    """What recording an answer needs of a run (pool threads do not touch the database)."""

    id: int
    since: float  # when it started running (UNIX time): bandwidth samples count from there
    constellation_id: int | None


class LiveReader:
    """One worker process's live reader: its threads, its questions still out."""

    def __init__(self, connections: ConnectionCache, threads: int = 16) -> None:
        self.connections = connections
        self.pid = os.getpid()
        self._pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="live")
        self._out: dict[tuple[int, str], Future[Answer]] = {}
        self._fc_asked: dict[int, float] = {}
        self._locks: dict[int, threading.Lock] = {}  # one writer of a run's figures at a time

    def refresh(self, config: Config) -> int:
        """Ask every running run's machines once; each answer is cached the moment it comes
        (not at the next refresh), so a slow answer is late by its own delay only."""
        runs = list(db.session.scalars(select(Run).where(Run.state == RunState.RUNNING)))
        client = connection(config)
        now = time.time()
        live = {run.id: run for run in runs}
        self._fc_asked = {k: v for k, v in self._fc_asked.items() if k in live}
        self._locks = {k: v for k, v in self._locks.items() if k in live}
        for run in runs:
            try:
                found = run_targets(run, config)
            except (CloudSimError, SSHError) as exc:
                log.warning("run %s: cannot reach its machines: %s", run.id, exc)
                continue
            ask_fc = now - self._fc_asked.get(run.id, 0.0) >= FC_EVERY_S
            if ask_fc:
                self._fc_asked[run.id] = now
            about = LiveRun(
                run.id, (run.running_at or run.started_at).timestamp(), run.constellation_id
            )
            lock = self._locks.setdefault(run.id, threading.Lock())
            for role, target in _roles(found, ask_fc):
                if (run.id, role) not in self._out:
                    self._out[run.id, role] = self._pool.submit(
                        self._answer, about, role, target, found, client, config, lock
                    )
        if self._out:  # the beat's pace: a question still out is not asked again
            wait(self._out.values(), timeout=config.run_live_seconds * 0.8)
        for key, future in list(self._out.items()):
            if future.done():
                del self._out[key]
                if future.exception() is not None:
                    log.warning("run %s: %s did not answer: %s", *key, future.exception())
        return len(runs)

    def _answer(
        self,
        run: LiveRun,
        role: str,
        target: SSHTarget,
        found: RunTargets,
        client: redis.Redis,
        config: Config,
        lock: threading.Lock,
    ) -> Answer:
        """Ask one machine and cache its answer (in a pool thread: SSH and Redis only)."""
        answer = self._ask(run.id, role, target, found)
        with lock:
            record(client, run, answer, config)
        return answer

    def _ask(self, run_id: int, role: str, target: SSHTarget, found: RunTargets) -> Answer:
        """Ask one machine."""
        executor = SSHExecutor(
            found.host_keys,
            secrets=[found.private_key],
            connect_policy=REACH,
            default_timeout=COMMAND_SECONDS,
            connections=self.connections,
        )
        machine = target.name.rsplit("/", 1)[-1]
        try:
            if role == "sim":
                return Answer(role, time.time(), ask_sim(executor, target, run_id), machine)
            if role == "router":
                counts = router_control.counters(executor, target)
                figures = {"used": payload_bits_used(counts), "spent_at": spent_at(counts)}
                return Answer(role, time.time(), figures, machine)
            executor.run(target, "true")
            return Answer(role, time.time(), None, machine)
        except (CloudSimError, SSHError, KeyError, TypeError, ValueError) as exc:
            # a command that ran and failed (csrouter restarting) says nothing against the
            # connection; closing it would also close those it carries (sim's, through router)
            if not isinstance(exc.__cause__ or exc, CommandFailed):
                self.connections.evict(target)
            raise


def _roles(found: RunTargets, with_fcs: bool) -> list[tuple[str, SSHTarget]]:
    roles = [("sim", found.sim)] + ([("router", found.router)] if found.router else [])
    if with_fcs:
        roles += [(name, found.by_name[name]) for name in found.fc_names if name in found.by_name]
    return roles


def ask_sim(executor: SSHExecutor, sim: SSHTarget, run_id: int) -> dict[str, Any]:
    """Return the run's live figures and score events, read on `sim`."""
    folder = run_dir(run_id)
    command = (
        f"cat {shlex.quote(f'{folder}/{LIVE}')} 2>/dev/null; echo; echo '#'; "
        f"cat {shlex.quote(f'{folder}/{SCORE}')} 2>/dev/null"
    )
    output = executor.run(sim, command).stdout
    live_text, _, score_text = output.partition("#\n")
    score = read_score_log(score_text.splitlines())
    figures = read_live(live_text.strip()) or {"sim_time": score.sim_seconds, "rtf": None}
    figures["sim_time"] = max(float(figures["sim_time"]), score.sim_seconds)
    figures["score"], figures["falls"] = score.score, score.falls
    figures["events"] = [
        {
            "kind": e.kind,
            "sim_time": e.sim_time,
            "wall_time": e.wall_time.isoformat(),
            "checkpoint": e.checkpoint,
            "points": e.points,
            "description": e.description,
        }
        for e in score.events
    ]
    return figures


def record(client: redis.Redis, run: LiveRun, answer: Answer, config: Config) -> None:
    """Merge one machine's answer into the run's cached figures."""
    key = KEY.format(run.id)
    raw = client.get(key)
    cached: dict[str, Any] = json.loads(raw) if raw else {"heard": {}}
    at = datetime.fromtimestamp(answer.at, UTC).isoformat()
    cached["heard"][answer.role] = at
    if answer.role == "sim" and answer.figures is not None:
        previous = cached.get("sim") or {}
        if answer.figures["sim_time"] > previous.get("sim_time", -1.0):
            cached["sim_advanced_at"] = at
        rtf = answer.figures.get("rtf")
        if rtf is not None and rtf < config.run_rtf_alert:
            cached["slow_since"] = cached.get("slow_since") or at
        else:
            cached["slow_since"] = None
        cached["events"] = answer.figures.pop("events")
        cached["sim"] = answer.figures
    if answer.role == "router" and answer.figures is not None:
        cached["used"] = answer.figures["used"]
        cached["spent_at"] = answer.figures["spent_at"]
        used = answer.figures["used"]
        sample = [round(answer.at - run.since, 2), used["uplink"], used["downlink"]]
        client.rpush(SAMPLES_KEY.format(run.id), json.dumps(sample))
        client.expire(SAMPLES_KEY.format(run.id), KEPT_SECONDS)
    client.set(key, json.dumps(cached), ex=KEPT_SECONDS)
    if run.constellation_id is not None and answer.machine:
        client.hset(HEARD_KEY.format(run.constellation_id), answer.machine, at)
        client.expire(HEARD_KEY.format(run.constellation_id), KEPT_SECONDS)


def machines_heard(config: Config, constellation_id: int) -> dict[str, str]:
    """Return when the live reader last heard from each machine of a constellation."""
    try:
        heard = connection(config).hgetall(HEARD_KEY.format(constellation_id))
    except redis.RedisError:
        return {}
    return {str(name): str(at) for name, at in heard.items()}


_reader: LiveReader | None = None


def reader() -> LiveReader:
    """Return this process's live reader (a forked worker process makes its own)."""
    global _reader
    if _reader is None or _reader.pid != os.getpid():
        _reader = LiveReader(process_cache())
    return _reader


@shared_task(name="cloudsim.competition.live")
def refresh_live_runs() -> int:
    """Read every running run's live figures into the cache; return how many runs."""
    return reader().refresh(current_app.config["CLOUDSIM"])
