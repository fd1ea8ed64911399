"""Runs with a simulator state log of a real run's size, uploaded to the portal (bench/portal).

A state log written by drcsim's own writer (`drcsim.runlog.RunLog`: a msgpack record at
100 Hz, the step, the simulated time, the 229 float32 values of vrc_task_2's state vector and
a 16-character digest: 969 bytes a record, 175 MB for 30 minutes) is generated once into a
temporary folder;
each sampled run declares it beside its score and bandwidth logs, and its instance sends it
as the outbox does (one run at a time, 8 MiB pieces at increasing offsets). The reference,
measured on the same bytes in the same run: a local copy of the file and its SHA-256, the
least the master must do with a log it receives.
"""

from __future__ import annotations

import hashlib
import json
import random
import shutil
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import requests
from drcsim.rundir import FINAL, STATE
from drcsim.runlog import RunLog

from bench.portal_ingest import INGEST, Uploader, record, small_logs
from cloudsim.portal.outbox import PIECE

STATE_FLOATS = 229  # vrc_task_2's state vector
HZ = 100
POOL = 512  # distinct state vectors the records cycle through


@dataclass(frozen=True)
class StateLog:
    """A generated state log on disk, with what its upload declares."""

    path: Path
    size: int
    sha256: str


def write_state_log(folder: Path, minutes: float) -> StateLog:
    """Write a state log of `minutes` of simulated time with drcsim's own run log writer."""
    rng = random.Random(11)
    pool = [[rng.uniform(-20, 20) for _ in range(STATE_FLOATS)] for _ in range(POOL)]
    log = RunLog(folder, {"bench": "portal"})
    for index in range(round(minutes * 60 * HZ)):  # 1 kHz physics, logged every 10th step
        log.state(10 * (index + 1), (index + 1) / HZ, pool[index % POOL])
    log.close({})
    final = json.loads((folder / FINAL).read_text())
    path = folder / STATE
    return StateLog(path, path.stat().st_size, final["state_log_sha256"])


@contextmanager
def state_log(minutes: float) -> Iterator[StateLog]:
    """Yield a generated state log in a temporary folder, removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="cloudsim-bench-state-"))
    try:
        yield write_state_log(folder, minutes)
    finally:
        shutil.rmtree(folder)


def reference(log: StateLog, folder: Path) -> dict[str, float]:
    """Time a local copy of the log into `folder` and its SHA-256 (seconds each); the copy is
    removed."""
    copy = folder / "reference-copy"
    started = time.perf_counter()
    shutil.copyfile(log.path, copy)
    copied = time.perf_counter() - started
    copy.unlink()
    started = time.perf_counter()
    with log.path.open("rb") as handle:
        checksum = hashlib.file_digest(handle, "sha256").hexdigest()
    hashed = time.perf_counter() - started
    assert checksum == log.sha256
    return {"copy": copied, "sha256": hashed}


def upload_large(base: str, uploaders: list[Uploader], log: StateLog) -> dict[str, Any]:
    """Send each uploader's extra run with the state log, one run after the other, the log in
    8 MiB pieces; return the seconds each took and the bytes sent."""
    small = small_logs()
    declared: list[dict[str, Any]] = [
        {"filename": x.filename, "kind": x.kind, "size": len(x.body), "sha256": x.sha256}
        for x in small
    ]
    declared.append({"filename": STATE, "kind": "state", "size": log.size, "sha256": log.sha256})
    seconds = []
    for me in uploaders:
        http = requests.Session()
        http.headers["Authorization"] = f"Bearer {me.token}"
        for remote_id, (task_id, start, name) in me.extra:
            url = f"{base}{INGEST}/{remote_id}"
            began = time.perf_counter()
            answers = [http.put(url, json={**record(me, task_id, start, name), "logs": declared})]
            for x in small:
                answers.append(_piece(http, f"{url}/logs/{x.filename}", 0, x.body))
            with log.path.open("rb") as handle:
                offset = 0
                while piece := handle.read(PIECE):
                    answers.append(_piece(http, f"{url}/logs/{STATE}", offset, piece))
                    offset += len(piece)
            answers.append(http.post(f"{url}/complete"))
            seconds.append(time.perf_counter() - began)
            refused = [f"{a.status_code} {a.text[:120]}" for a in answers if not a.ok]
            if refused or not answers[-1].json()["complete"]:
                raise SystemExit(f"a large upload was refused: {refused[:3]}")
    return {"runs": len(seconds), "seconds": seconds, "bytes": log.size}


def _piece(http: requests.Session, url: str, offset: int, body: bytes) -> requests.Response:
    return http.put(
        url,
        params={"offset": offset},
        data=body,
        headers={"Content-Type": "application/octet-stream"},
    )
