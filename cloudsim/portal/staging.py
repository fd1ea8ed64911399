"""On the master: the parts of logs still arriving from team instances, and their cleaning.

A log's bytes received so far wait in INSTANCE_DIR/portal/staging/{run id}/{name}.part until
the log is whole. A piece being received holds an exclusive lock on its part file; nothing
here removes a locked part, so a piece under way is never cut. The parts of a run whose
upload was refused for good are removed at once (`discard_run`); a part that has not grown
for CLOUDSIM_PORTAL_STAGING_HOURS is removed by the beat (`clean_abandoned`): an instance
that comes back later is told the master has 0 bytes and sends that log again.

A part's SHA-256 is computed as its pieces arrive (`running_sha256`, `keep_sha256`): this
process keeps each part's running hash after its last piece, so a whole log is not read again;
a part this process did not see last (another worker, a restart) is read once, then followed.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import threading
import time
from collections import OrderedDict
from datetime import timedelta
from pathlib import Path
from typing import IO, TYPE_CHECKING

from celery import shared_task
from flask import current_app

from cloudsim.config import Config

if TYPE_CHECKING:
    from hashlib import _Hash

TASK = "cloudsim.portal.clean_staging"
EVERY = timedelta(hours=1)
HASHES_KEPT = 256  # running hashes of parts kept per process (~0.2 kB each); the rest read again
READ = 8 * 1024 * 1024

# part -> (what the part was when its hash was kept: inode, size, mtime; its running SHA-256)
_hashes: OrderedDict[Path, tuple[tuple[int, int, int], _Hash]] = OrderedDict()
_hashes_lock = threading.Lock()


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


def _identity(handle: IO[bytes]) -> tuple[int, int, int]:
    """Say which bytes a part holds: a part removed and made again differs in inode or mtime."""
    stat = os.fstat(handle.fileno())
    return stat.st_ino, stat.st_size, stat.st_mtime_ns


def running_sha256(part: Path, handle: IO[bytes]) -> _Hash:
    """Return the SHA-256 state of what a part holds, its handle locked: the one kept after its
    last piece in this process, else read from the part once."""
    with _hashes_lock:
        kept = _hashes.pop(part, None)
    if kept is not None and kept[0] == _identity(handle):
        return kept[1]
    digest = hashlib.sha256()
    size = _identity(handle)[1]
    with part.open("rb") as reader:  # the locked part itself: it is only removed under the lock
        while size > 0 and (chunk := reader.read(min(READ, size))):
            digest.update(chunk)
            size -= len(chunk)
    return digest


def keep_sha256(part: Path, handle: IO[bytes], digest: _Hash) -> None:
    """Keep a part's running SHA-256 after a piece was written (and flushed) to it."""
    with _hashes_lock:
        _hashes[part] = (_identity(handle), digest)
        while len(_hashes) > HASHES_KEPT:
            _hashes.popitem(last=False)


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
