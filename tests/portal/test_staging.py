"""The master's parts of logs still arriving: a refused run's removed at once, an abandoned
one's removed by the beat after CLOUDSIM_PORTAL_STAGING_HOURS, one under way never; a part's
running SHA-256 kept only while the part holds what it was kept for."""

from __future__ import annotations

import fcntl
import hashlib
import os
import time
from collections.abc import Callable, Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    PortalRefusal,
    Team,
    utcnow,
)
from cloudsim.portal import staging
from tests.competition.support import open_task
from tests.conftest import running_app
from tests.portal.support import uploader

LOG = os.urandom(4000)
HOURS = 48


@pytest.fixture
def master(make_config: Callable[..., Config]) -> Iterator[Flask]:
    with running_app(make_config(portal_url="https://127.0.0.1:5443/")) as app:
        yield app


def _put(master: Flask, token: dict[str, str], url: str, data: bytes) -> Any:
    return master.test_client().put(
        url, data=data, headers=token, content_type="application/octet-stream"
    )


def test_a_refused_runs_parts_go_at_once_abandoned_ones_with_the_beat(
    master: Flask, team_a: Team
) -> None:
    config: Config = master.config["CLOUDSIM"]
    token, record = uploader(team_a, LOG)
    client = master.test_client()
    base = "/api/v1/portal/ingest/runs"
    runs = {}
    for remote in (1, 2, 3, 4):  # its runs of four tasks: one task each
        if remote > 1:
            task = open_task(team_a.id, window_start=utcnow() - timedelta(hours=1))
            record = dict(record, task_key=f"m{task.id}", task_name=task.name)
        sent = client.put(f"{base}/{remote}", json=record, headers=token)
        assert sent.status_code == 200, sent.json
        runs[remote] = sent.json["run_id"]
        first = _put(master, token, f"{base}/{remote}/logs/a.bin?offset=0", LOG[:1000])
        assert first.status_code == 200, first.json

    def part(remote: int, name: str = "a.bin") -> Path:
        return staging.part_path(config, runs[remote], name)

    # run 1: b.bin's bytes overrun what was declared: refused for good, a.bin's part goes too
    over = _put(master, token, f"{base}/1/logs/b.bin?offset=0", LOG + b"more")
    assert over.status_code == 403 and "more bytes" in over.json["message"]
    assert not part(1).exists() and not part(1).parent.exists()
    assert db.session.scalar(select(PortalRefusal.run_id)) == runs[1]
    # runs 2 to 4 stopped arriving; 2 and 4 long ago, 4 with a piece arriving right now
    old = time.time() - (HOURS + 1) * 3600
    for remote in (2, 4):
        os.utime(part(remote), (old, old))
    recent = time.time() - (HOURS - 1) * 3600
    os.utime(part(3), (recent, recent))
    with part(4).open("ab") as arriving:
        fcntl.flock(arriving, fcntl.LOCK_EX)  # as a piece being received holds it
        assert staging.TASK in master.extensions["celery"].conf.beat_schedule
        assert master.extensions["celery"].tasks[staging.TASK].apply().get() == 1
    assert not part(2).exists() and not part(2).parent.exists()
    assert part(3).stat().st_size == 1000 and part(4).stat().st_size == 1000
    # run 2's instance comes back: told the master has nothing, it sends the log again
    late = _put(master, token, f"{base}/2/logs/a.bin?offset=1000", LOG[1000:])
    assert late.status_code == 409 and late.json["received"] == 0
    for name in ("a.bin", "b.bin"):
        whole = _put(master, token, f"{base}/2/logs/{name}?offset=0", LOG)
        assert whole.status_code == 200 and whole.json["complete"], whole.json
    assert client.post(f"{base}/2/complete", headers=token).status_code == 200
    assert not part(2).parent.exists()  # its folder went with its last part
    # run 3 goes on from where it was
    assert _put(master, token, f"{base}/3/logs/a.bin?offset=1000", LOG[1000:]).json["complete"]


def test_a_parts_running_hash_is_kept_only_while_it_is_what_the_part_holds(
    tmp_path: Path,
) -> None:
    part = tmp_path / "1" / "a.bin.part"

    def receive(piece: bytes) -> Any:  # as a piece is received: the hash, then kept after it
        with staging.open_part(part) as staged:
            digest = staging.running_sha256(part, staged)
            staged.write(piece)
            staged.flush()
            digest.update(piece)
            staging.keep_sha256(part, staged, digest)
            return digest

    kept = receive(b"one")
    with staging.open_part(part) as staged:  # the next piece in this process: the kept hash
        assert staging.running_sha256(part, staged) is kept
    receive(b"two")
    with part.open("ab") as other:  # another worker appends: the part is read again
        other.write(b"three")
    assert receive(b"four").hexdigest() == hashlib.sha256(b"onetwothreefour").hexdigest()
    part.unlink()  # removed and made again, as long (its mtime tells them apart)
    part.write_bytes(b"ONETWOTHREEFOUR")
    os.utime(part, ns=(1, 1))
    with staging.open_part(part) as staged:
        assert (
            staging.running_sha256(part, staged).hexdigest()
            == hashlib.sha256(b"ONETWOTHREEFOUR").hexdigest()
        )
