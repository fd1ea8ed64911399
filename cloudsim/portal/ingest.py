"""On the master: the runs and logs team instances upload, checked before they count.

A run record becomes one of the master's own runs (score events included), marked with the
instance and the instance's id for it: sending it again returns the same run, never a second
one. Its logs arrive in pieces at increasing offsets (`receive_chunk`): the bytes received so
far are kept in a staging file, so an upload cut off halfway continues from what arrived; a
log is stored (and listed on the run) only once its size and SHA-256 (computed as the pieces
arrive) are the declared ones.
What fails a check is refused with the reason (`Refused`) and the API records it.
"""

from __future__ import annotations

import fcntl
import hashlib
import re
from datetime import datetime, timedelta
from pathlib import Path
from typing import IO, Any

from flask import current_app
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from werkzeug.exceptions import ClientDisconnected

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.config import Config
from cloudsim.errors import CloudSimError, Conflict, NotFound
from cloudsim.extensions import db
from cloudsim.models import Artifact, Run, RunState, ScoreEvent, Task, TeamInstance, utcnow
from cloudsim.portal import staging
from cloudsim.verification.service import request_verification
from cloudsim.web.inputs import as_id

TASK_KEY = re.compile(r"^m([0-9]{1,12})$")  # the master's task, as its instances name it
PIECE = 1024 * 1024
EMPTY_SHA256 = hashlib.sha256(b"").hexdigest()


class Refused(CloudSimError):
    """A result the master does not take: the reason is recorded and shown to officers."""

    status = 403

    def __init__(self, message: str, run_id: int | None = None, **detail: Any) -> None:
        super().__init__(message)
        self.run_id = run_id
        self.detail = detail


class ChecksumMismatch(Refused):
    """A whole log whose SHA-256 is not the declared one: recorded, and sent again from 0."""

    status = 422


class OffsetMismatch(Conflict):
    """A log's piece does not start where the master's copy ends (it says where)."""

    def __init__(self, filename: str, received: int) -> None:
        super().__init__(f"{filename}: the master has {received} bytes; send from there")
        self.received = received


def uploaded_run(instance: TeamInstance, remote_id: int) -> Run | None:
    """Return the master's run for an instance's run, if it was received."""
    return db.session.scalar(
        select(Run).where(Run.instance_id == instance.id, Run.remote_run_id == remote_id)
    )


def _run_of(instance: TeamInstance, remote_id: int) -> Run:
    run = uploaded_run(instance, remote_id)
    if run is None:
        raise NotFound.of("uploaded run", remote_id)
    return run


def _task_for(instance: TeamInstance, record_: dict[str, Any]) -> Task:
    """Return the master's task the run was made of, if it was scheduled for the instance's
    team; refuse otherwise."""
    team = instance.team
    if team is None:
        raise Refused(f"{instance.name} serves no team: it may not send results")
    if record_["team"] != team.name:
        raise Refused(
            f"a result for team {record_['team']!r}: {instance.name} serves {team.name!r} only"
        )
    match = TASK_KEY.match(record_["task_key"])
    task_id = as_id(match.group(1)) if match else None  # past int32: no such row (and no 5xx)
    task = db.session.get(Task, task_id) if task_id is not None else None
    if task is None or task.team_id != team.id:
        raise Refused(
            f"task {record_['task_key']!r} ({record_['task_name']!r}) was not scheduled "
            f"for {team.name}"
        )
    if (task.world, task.run_config) != (record_["world"], record_["run_config"]):
        raise Refused(
            f"the run was of {record_['world']} #{record_['run_config']}, its task "
            f"{task.name!r} is {task.world} #{task.run_config}"
        )
    terms = (task.uplink_bits, task.downlink_bits, task.timeout_s)
    sent = (record_["uplink_bits"], record_["downlink_bits"], record_["timeout_s"])
    if sent != terms:
        raise Refused(
            f"the run's caps and timeout {sent} are not its task's {terms} (uplink bits, "
            "downlink bits, seconds)"
        )
    return task


def _check_window(task: Task, record_: dict[str, Any], config: Config) -> None:
    started: datetime = record_["started_at"]
    finished: datetime | None = record_["finished_at"]
    if record_["state"] not in (RunState.FINISHED.value, RunState.ERROR.value) or finished is None:
        raise Refused(f"the run has not ended ({record_['state']})")
    if not task.window_start <= started < task.window_stop:
        raise Refused(
            f"the run started at {started:%Y-%m-%d %H:%M:%S} UTC, outside its task's window "
            f"({task.window_start:%Y-%m-%d %H:%M} to {task.window_stop:%Y-%m-%d %H:%M} UTC)"
        )
    latest = task.window_stop + timedelta(seconds=config.portal_window_grace_seconds)
    if finished > latest or finished < started:
        raise Refused(
            f"the run ended at {finished:%Y-%m-%d %H:%M:%S} UTC, outside its task's window "
            f"(closed {task.window_stop:%Y-%m-%d %H:%M} UTC, "
            f"{config.portal_window_grace_seconds} s allowed to stop)"
        )


def counted_run(task_id: int, other_than: int | None = None) -> Run | None:
    """Return the task's finished run that counts (not invalidated), if any but `other_than`."""
    query = select(Run).where(
        Run.task_id == task_id, Run.state == RunState.FINISHED, Run.invalidated_at.is_(None)
    )
    if other_than is not None:
        query = query.where(Run.id != other_than)
    return db.session.scalar(query)


def _check_once(
    task: Task, record_: dict[str, Any], instance: TeamInstance, remote_id: int
) -> Run | None:
    """Refuse a second finished run of a task; return the run itself if it is the one the
    task has (the same record sent twice at once: the other request stored it meanwhile)."""
    if record_["state"] != RunState.FINISHED.value:
        return None
    other = counted_run(task.id)
    if other is None:
        return None
    if (other.instance_id, other.remote_run_id) == (instance.id, remote_id):
        return other
    raise Refused(f"task {task.name!r} already has a finished run (run {other.id})")


def receive_run(instance: TeamInstance, remote_id: int, record_: dict[str, Any]) -> Run:
    """Take an instance's finished run as the master's own (the same run if sent before)."""
    existing = uploaded_run(instance, remote_id)
    if existing is not None:
        return existing
    # here, not at the top: the figures' checks raise this module's Refused
    from cloudsim.portal.plausibility import check_figures

    config: Config = current_app.config["CLOUDSIM"]
    task = _task_for(instance, record_)
    _check_window(task, record_, config)
    check_figures(task, record_)
    twin = _check_once(task, record_, instance, remote_id)
    if twin is not None:
        return twin
    names = [log["filename"] for log in record_["logs"]]
    if len(set(names)) != len(names):
        raise Refused("a log file is listed twice")
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        instance_id=instance.id,
        remote_run_id=remote_id,
        uploaded_at=utcnow(),
        upload_manifest=record_["logs"],
        **{
            name: record_[name]
            for name in (
                "end_reason",
                "stop_reason",
                "error",
                "score",
                "falls",
                "sim_seconds",
                "uplink_bits_used",
                "downlink_bits_used",
                "uplink_spent_at",
                "downlink_spent_at",
                "started_at",
                "running_at",
                "finished_at",
            )
        },
        state=RunState(record_["state"]),
    )
    run.score_events = [ScoreEvent(**event) for event in record_["score_events"]]
    if not names:
        run.logs_complete_at = utcnow()
    db.session.add(run)
    try:
        db.session.flush()
    except IntegrityError:  # another request stored this run, or the task's finished run, at once
        db.session.rollback()
        twin = uploaded_run(instance, remote_id) or _check_once(task, record_, instance, remote_id)
        if twin is None:
            raise
        return twin
    for log in record_["logs"]:
        if log["size"] == 0:  # no piece will ever come: stored now (its checksum checked)
            part = _staged(run, log["filename"])
            staging.open_part(part).close()
            _store(run, log, part, EMPTY_SHA256)
    record(
        "portal.receive",
        SYSTEM,
        target_type="run",
        target_id=run.id,
        team_id=run.team_id,
        instance=instance.name,
        remote_run_id=remote_id,
        score=run.score,
    )
    return run


def _declared(run: Run, filename: str) -> dict[str, Any]:
    for log in run.upload_manifest or ():
        if log["filename"] == filename:
            return log
    raise NotFound.of("log", filename)


def _staged(run: Run, filename: str) -> Path:
    return staging.part_path(current_app.config["CLOUDSIM"], run.id, filename)


def log_status(run: Run, filename: str) -> dict[str, Any]:
    """Return how much of a declared log the master has, and whether it is stored."""
    log = _declared(run, filename)
    stored = artifact_for(run, filename) is not None
    part = _staged(run, filename)
    received = log["size"] if stored else (part.stat().st_size if part.exists() else 0)
    return {
        "filename": filename,
        "size": log["size"],
        "sha256": log["sha256"],
        "received": received,
        "complete": stored,
    }


def run_status(run: Run) -> dict[str, Any]:
    """Return the master's run id, its logs' status, and whether every log is stored."""
    logs = [log_status(run, log["filename"]) for log in run.upload_manifest or ()]
    return {"run_id": run.id, "logs": logs, "complete": run.logs_complete_at is not None}


def receive_chunk(
    instance: TeamInstance, remote_id: int, filename: str, offset: int, body: IO[bytes]
) -> dict[str, Any]:
    """Append a piece of a log at `offset`; store the log once whole and its checksum right."""
    run = _run_of(instance, remote_id)
    log = _declared(run, filename)
    if artifact_for(run, filename) is not None:
        return log_status(run, filename)  # a repeated last piece: stored already
    part = _staged(run, filename)
    with staging.open_part(part) as staged:
        try:
            fcntl.flock(staged, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise Conflict(f"{filename}: another piece is being received") from None
        if staging.removed_meanwhile(staged):
            raise OffsetMismatch(filename, 0)  # cleaned as abandoned: the log starts again
        received = staged.seek(0, 2)
        if offset != received:
            raise OffsetMismatch(filename, received)
        digest = staging.running_sha256(part, staged)
        try:
            while piece := body.read(PIECE):
                staged.write(piece)
                digest.update(piece)
                if staged.tell() > log["size"]:
                    break
        except ClientDisconnected:
            pass  # what arrived is kept: the next piece starts from there
        staged.flush()
        received = staged.tell()
        if received < log["size"]:
            staging.keep_sha256(part, staged, digest)
    if received > log["size"]:
        part.unlink()
        raise Refused(
            f"{filename}: more bytes than the {log['size']} declared", run.id, filename=filename
        )
    if received == log["size"]:
        _store(run, log, part, digest.hexdigest())
    return log_status(run, filename)


def _store(run: Run, log: dict[str, Any], part: Path, checksum: str) -> None:
    if checksum != log["sha256"]:
        part.unlink()  # the instance sends it again from the start
        raise ChecksumMismatch(
            f"{log['filename']}: checksum mismatch (declared {log['sha256'][:12]}, received "
            f"{checksum[:12]}); send it again",
            run.id,
            filename=log["filename"],
        )
    name = LogStore.object_name(run.id, log["filename"])
    LogStore(current_app.config["CLOUDSIM"]).keep(part, name)
    db.session.add(
        Artifact(
            run=run,
            kind=log["kind"],
            filename=log["filename"],
            location=name,
            size=log["size"],
            sha256=checksum,
        )
    )
    db.session.flush()
    if all(artifact_for(run, other["filename"]) for other in run.upload_manifest or ()):
        run.logs_complete_at = utcnow()
        staging.discard_run(current_app.config["CLOUDSIM"], run.id)  # its folder, now empty
        db.session.flush()
        request_verification(run.id)  # now, not at the next sweep


def complete(instance: TeamInstance, remote_id: int) -> Run:
    """Acknowledge an upload: every declared log is stored (409 naming those still missing)."""
    run = _run_of(instance, remote_id)
    missing = [log["filename"] for log in run_status(run)["logs"] if not log["complete"]]
    if missing:
        raise Conflict(f"logs not received yet: {', '.join(missing)}")
    return run
