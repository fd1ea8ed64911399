"""Runs with a simulator state log of a real run's size, uploaded to the portal (bench/portal).

A state log as drcsim writes it (`drcsim.runlog`: a msgpack record at 100 Hz, the step, the
simulated time, the 229 float32 values of vrc_task_2's state vector and a 16-character
digest: 969 bytes a record, 175 MB for 30 minutes) is generated once into a temporary file;
each sampled run declares it beside its score and bandwidth logs, and its instance sends it
as the outbox does (one run at a time, 8 MiB pieces at increasing offsets). The reference,
measured on the same bytes in the same run: a local copy of the file and its SHA-256, the
least the master must do with a log it receives.
"""

from __future__ import annotations

import hashlib
import random
import shutil
import struct
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import requests

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


def write_state_log(path: Path, minutes: float) -> StateLog:
    """Write a state log of `minutes` of simulated time in drcsim's format."""
    rng = random.Random(11)
    pool = [
        struct.pack(f"<{STATE_FLOATS}f", *(rng.uniform(-20, 20) for _ in range(STATE_FLOATS)))
        for _ in range(POOL)
    ]
    packer = msgpack.Packer()
    digest = hashlib.sha256()
    with path.open("wb") as out:
        batch = bytearray()
        for index in range(round(minutes * 60 * HZ)):
            batch += packer.pack(
                {
                    "step": 10 * (index + 1),  # 1 kHz physics, logged every 10th step
                    "t": (index + 1) / HZ,
                    "state32": pool[index % POOL],
                    "digest": f"{rng.getrandbits(64):016x}",
                }
            )
            if len(batch) >= PIECE:
                digest.update(batch)
                out.write(batch)
                batch.clear()
        digest.update(batch)
        out.write(batch)
    return StateLog(path, path.stat().st_size, digest.hexdigest())


@contextmanager
def state_log(minutes: float) -> Iterator[StateLog]:
    """Yield a generated state log in a temporary folder, removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="cloudsim-bench-state-"))
    try:
        yield write_state_log(folder / "state.msgpack", minutes)
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
    declared.append(
        {"filename": "state.msgpack", "kind": "state", "size": log.size, "sha256": log.sha256}
    )
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
                    answers.append(_piece(http, f"{url}/logs/state.msgpack", offset, piece))
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
