"""On a team instance: send every finished run and its logs to the master's portal.

Every CLOUDSIM_PORTAL_UPLOAD_SECONDS the beat starts `cloudsim.portal.upload`: it adds an
outbox row for each ended run of the master's tasks that has none, then sends the rows
oldest first, one at a time (a Redis lock): the run record, then each log from the offset
the master says it has, in pieces of 8 MiB, then asks the master to acknowledge. A failure
(the master unreachable, a 5xx, a log refused for its checksum) waits, doubling from
CLOUDSIM_PORTAL_RETRY_SECONDS up to 10 minutes, and holds the rows after it, so runs arrive
in order; a refusal (a 4xx saying why) is final for that row and holds nothing.

While the master does not answer at all, a cheap probe (every PROBE_EVERY) asks it whether it
is back; the first answer ends the wait and sends the outbox at once, so a master outage
delays the portal by seconds, not by the backoff.
"""

from __future__ import annotations

from collections.abc import Iterator
from datetime import timedelta
from typing import Any

import redis
from celery import shared_task
from flask import current_app
from redis.lock import Lock
from sqlalchemy import select, update

from cloudsim.competition.artifacts import LogStore
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    Artifact,
    PortalUpload,
    Run,
    RunState,
    Task,
    UploadState,
    utcnow,
)
from cloudsim.portal.credentials import portal_endpoint
from cloudsim.team_instances.client import (
    CallRefused,
    Endpoint,
    InstanceError,
    PinMismatch,
    call,
)
from cloudsim.team_instances.sync import release

PIECE = 8 * 1024 * 1024
MAX_WAIT_SECONDS = 600
LOCK_SECONDS = 120  # renewed after every piece: a dead uploader frees it this soon
CHECKSUM_TRIES = 3  # a log refused for its checksum this often: the upload is refused
FINAL = (400, 403, 404)  # the master refused the result itself: sending it again cannot help
TASK = "cloudsim.portal.upload"
PROBE_TASK = "cloudsim.portal.probe"
PROBE_EVERY = timedelta(seconds=2)
PROBE_TIMEOUT = 1.5
MASTER_DOWN_KEY = "cloudsim:portal:master-down"  # set while the master does not answer


class UploadFailed(Exception):
    """This try did not reach the end; the row waits and tries again."""


def queue_ended_runs() -> int:
    """Add an outbox row for every ended run of the master's tasks without one."""
    ended = (
        select(Run.id)
        .join(Task, Run.task_id == Task.id)
        .outerjoin(PortalUpload, PortalUpload.run_id == Run.id)
        .where(
            Run.state.in_((RunState.FINISHED, RunState.ERROR)),
            Task.master_key.is_not(None),
            PortalUpload.id.is_(None),
        )
        .order_by(Run.finished_at, Run.id)
    )
    ids = list(db.session.scalars(ended))
    for run_id in ids:
        db.session.add(PortalUpload(run_id=run_id))
    db.session.flush()
    return len(ids)


def run_record(run: Run) -> dict[str, Any]:
    """Return the run as the portal takes it (times in ISO 8601 UTC), its logs declared."""
    task = run.task

    def when(value: Any) -> str | None:
        return value.isoformat() if value is not None else None

    return {
        "team": run.team.name,
        "task_key": task.master_key,
        "task_name": task.name,
        "world": task.world,
        "run_config": task.run_config,
        "state": run.state.value,
        "stop_reason": run.stop_reason,
        "end_reason": run.end_reason,
        "error": run.error,
        "score": run.score,
        "falls": run.falls,
        "sim_seconds": run.sim_seconds,
        "uplink_bits_used": run.uplink_bits_used,
        "downlink_bits_used": run.downlink_bits_used,
        "uplink_bits": task.uplink_bits,
        "downlink_bits": task.downlink_bits,
        "timeout_s": task.timeout_s,
        "seconds_left": max(0.0, task.timeout_s - run.sim_seconds),
        "uplink_spent_at": when(run.uplink_spent_at),
        "downlink_spent_at": when(run.downlink_spent_at),
        "started_at": when(run.started_at),
        "running_at": when(run.running_at),
        "finished_at": when(run.finished_at),
        "score_events": [
            {
                "kind": event.kind,
                "checkpoint": event.checkpoint,
                "points": event.points,
                "sim_time": event.sim_time,
                "wall_time": when(event.wall_time),
                "description": event.description,
            }
            for event in run.score_events
        ],
        "logs": [
            {"filename": a.filename, "kind": a.kind, "size": a.size, "sha256": a.sha256}
            for a in _logs(run)
        ],
    }


def _logs(run: Run) -> list[Artifact]:
    return sorted(run.artifacts, key=lambda a: a.id)


def _pieces(store: LogStore, artifact: Artifact, offset: int) -> Iterator[bytes]:
    """Yield a stored log from offset on, in pieces of PIECE bytes."""
    buffer = bytearray()
    for chunk in store.stream_from(artifact.location, offset):
        buffer += chunk
        while len(buffer) >= PIECE:
            yield bytes(buffer[:PIECE])
            del buffer[:PIECE]
    if buffer:
        yield bytes(buffer)


class _Sender:
    """One try at one outbox row: every step commits its progress (shown on the run page)."""

    def __init__(self, upload: PortalUpload, endpoint: Endpoint, lock: Lock) -> None:
        self.upload, self.endpoint, self.lock = upload, endpoint, lock
        self.run = upload.run
        self.base = f"/portal/ingest/runs/{self.run.id}"
        self.store = LogStore(current_app.config["CLOUDSIM"])

    def _progress(self, received: dict[str, int]) -> None:
        self.upload.bytes_sent = sum(received.values())
        db.session.commit()
        self.lock.reacquire()

    def send(self) -> None:
        upload, logs = self.upload, _logs(self.run)
        upload.state = UploadState.UPLOADING
        upload.bytes_total = sum(a.size for a in logs)
        status = call(self.endpoint, "PUT", self.base, run_record(self.run), timeout=30)
        upload.master_run_id = status["run_id"]
        received = {log["filename"]: int(log["received"]) for log in status["logs"]}
        self._progress(received)
        for artifact in logs:
            if artifact.filename not in received:
                raise InstanceError(f"the master has no {artifact.filename} listed for the run")
            while received[artifact.filename] < artifact.size:
                received[artifact.filename] = self._send_log(artifact, received)
                self._progress(received)
        call(self.endpoint, "POST", f"{self.base}/complete", timeout=30)
        upload.state, upload.uploaded_at = UploadState.UPLOADED, utcnow()
        upload.error, upload.attempts = None, 0

    def _send_log(self, artifact: Artifact, received: dict[str, int]) -> int:
        """Send a log from where the master's copy ends; return where it ends now."""
        offset = received[artifact.filename]
        path = f"{self.base}/logs/{artifact.filename}"
        for piece in _pieces(self.store, artifact, offset):
            try:
                answer = call(
                    self.endpoint, "PUT", f"{path}?offset={offset}", data=piece, timeout=120
                )
            except CallRefused as exc:
                if exc.code == 409 and isinstance(exc.answer, dict) and "received" in exc.answer:
                    return int(exc.answer["received"])  # the master has more (or less): from there
                raise
            offset = int(answer["received"])
            received[artifact.filename] = offset
            self._progress(received)
            if answer["complete"]:
                return artifact.size
        return offset


def _wait(upload: PortalUpload, error: str, config: Config) -> None:
    upload.attempts += 1
    seconds = min(config.portal_retry_seconds * 2 ** (upload.attempts - 1), MAX_WAIT_SECONDS)
    upload.next_attempt_at = utcnow() + timedelta(seconds=seconds)
    upload.error = f"{error} (try {upload.attempts}; next in {seconds} s)"


def _refuse(upload: PortalUpload, error: str) -> None:
    upload.state, upload.error = UploadState.REFUSED, error


def _redis(config: Config) -> redis.Redis:
    return redis.Redis.from_url(config.effective_redis_url, socket_timeout=5)


def _uploader_lock(config: Config) -> Lock:
    return _redis(config).lock("cloudsim:portal:upload", timeout=LOCK_SECONDS)


def master_answers(endpoint: Endpoint) -> bool:
    """Return whether the master's portal answers at all (any answer below 500)."""
    try:
        # run 0 is never uploaded: a 404 from the master's ingest is the cheapest answer
        call(endpoint, "GET", "/portal/ingest/runs/0", timeout=PROBE_TIMEOUT)
    except CallRefused as exc:
        return exc.code < 500
    except (InstanceError, OSError):
        return False
    return True


def probe_master(config: Config) -> int:
    """While the master was unreachable: once it answers, end the outbox's wait and send it
    now; return how many runs were acknowledged."""
    client = _redis(config)
    if not client.exists(MASTER_DOWN_KEY):
        return 0
    endpoint = portal_endpoint()
    if endpoint is None or not master_answers(endpoint):
        return 0
    client.delete(MASTER_DOWN_KEY)
    waiting = PortalUpload.state.in_((UploadState.PENDING, UploadState.UPLOADING))
    db.session.execute(update(PortalUpload).where(waiting).values(next_attempt_at=utcnow()))
    db.session.commit()
    return upload_outbox(config)


def upload_outbox(config: Config) -> int:
    """Send the due outbox rows in order; return how many were acknowledged."""
    endpoint = portal_endpoint()
    if endpoint is None:
        return 0  # not a team instance (or its master has no portal yet)
    lock = _uploader_lock(config)
    if not lock.acquire(blocking=False):
        return 0  # another worker is sending: rows go one at a time, in order
    sent = 0
    try:
        queue_ended_runs()
        db.session.commit()
        pending = select(PortalUpload).where(
            PortalUpload.state.in_((UploadState.PENDING, UploadState.UPLOADING))
        )
        for upload in list(db.session.scalars(pending.order_by(PortalUpload.id))):
            if upload.next_attempt_at > utcnow():
                break  # the oldest waits: the ones after it wait too (order)
            try:
                _Sender(upload, endpoint, lock).send()
                sent += 1
            except CallRefused as exc:
                db.session.rollback()
                message = exc.answer.get("message") if isinstance(exc.answer, dict) else None
                reason = f"{exc.code}: {message or exc}"
                if exc.code in FINAL or (exc.code == 422 and upload.attempts + 1 >= CHECKSUM_TRIES):
                    _refuse(upload, reason)
                else:
                    _wait(upload, reason, config)
                    db.session.commit()
                    break
            except (InstanceError, OSError) as exc:
                db.session.rollback()
                _wait(upload, str(exc), config)
                db.session.commit()
                if not isinstance(exc, PinMismatch):  # not the master at all: no probing
                    _redis(config).set(MASTER_DOWN_KEY, "1")
                break
            db.session.commit()
    finally:
        release(lock)
    return sent


@shared_task(name=TASK)
def upload() -> int:
    """Send finished runs and their logs to the master's portal (beat)."""
    return upload_outbox(current_app.config["CLOUDSIM"])


@shared_task(name=PROBE_TASK)
def probe() -> int:
    """While the master is unreachable, notice at once when it answers again (beat)."""
    return probe_master(current_app.config["CLOUDSIM"])
