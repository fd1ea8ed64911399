"""On the master: the parts of logs still arriving from team instances, and their cleaning.

A log's bytes received so far wait in INSTANCE_DIR/portal/staging/{run id}/{name}.part until
the log is whole. A piece being received holds an exclusive lock on its part file; nothing
here removes a locked part, so a piece under way is never cut. The parts of a run whose
upload was refused for good are removed at once (`discard_run`); a part that has not grown
for CLOUDSIM_PORTAL_STAGING_HOURS is removed by the beat (`clean_abandoned`): an instance
that comes back later is told the master has 0 bytes and sends that log again.
"""

from __future__ import annotations

import fcntl
import os
import time
from datetime import timedelta
from pathlib import Path
from typing import IO

from celery import shared_task
from flask import current_app

from cloudsim.config import Config

TASK = "cloudsim.portal.clean_staging"
EVERY = timedelta(hours=1)


def root(config: Config) -> Path:
    """Return the folder the parts of arriving logs are kept in."""
    return config.instance_dir / "portal" / "staging"


def part_path(config: Config, run_id: int, filename: str) -> Path:
    """Return where the part of a run's log received so far is kept."""
    return root(config) / str(run_id) / f"{filename}.part"


def open_part(part: Path) -> IO[bytes]:
    """Open a part for appending, its run's folder made (again, if the beat just dropped it)."""
    for _ in range(3):
        part.parent.mkdir(parents=True, exist_ok=True)
        try:
            return part.open("ab")
        except FileNotFoundError:
            continue  # the folder was empty and the beat removed it between the two calls
    raise FileNotFoundError(part)


def removed_meanwhile(handle: IO[bytes]) -> bool:
    """Say whether a part was removed while its opener waited for the lock."""
    return os.fstat(handle.fileno()).st_nlink == 0


def _remove_idle(part: Path, older_than: float | None) -> bool:
    """Remove a part unless a piece is being written to it (or it grew since `older_than`)."""
    try:
        handle = part.open("rb")
    except FileNotFoundError:
        return False
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False  # a piece is arriving: it is under way
        if older_than is not None and os.fstat(handle.fileno()).st_mtime >= older_than:
            return False
        part.unlink(missing_ok=True)  # under the lock: a piece waiting for it sees it unlinked
        return True


def _drop_empty(folder: Path) -> None:
    try:
        folder.rmdir()
    except OSError:
        pass  # not empty (a part still arriving), or gone already


def discard_run(config: Config, run_id: int) -> int:
    """Remove the parts of a run's logs (its upload was refused); return how many."""
    folder = root(config) / str(run_id)
    removed = sum(_remove_idle(part, None) for part in folder.glob("*.part"))
    _drop_empty(folder)
    return removed


def clean_abandoned(config: Config) -> int:
    """Remove the parts that have not grown for CLOUDSIM_PORTAL_STAGING_HOURS; return how many."""
    cutoff = time.time() - config.portal_staging_hours * 3600
    removed = 0
    for folder in root(config).glob("*"):
        removed += sum(_remove_idle(part, cutoff) for part in folder.glob("*.part"))
        _drop_empty(folder)
    return removed


@shared_task(name=TASK)
def clean_staging() -> int:
    """Remove the parts of logs whose upload stopped arriving long ago (beat, hourly)."""
    return clean_abandoned(current_app.config["CLOUDSIM"])
