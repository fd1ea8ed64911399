"""Short writes on a busy database: retried when they must land, skipped when they may not."""

from __future__ import annotations

import logging
import random
import time
from collections.abc import Callable
from typing import TypeVar

from sqlalchemy import Executable
from sqlalchemy.engine import Engine
from sqlalchemy.exc import OperationalError

log = logging.getLogger(__name__)
T = TypeVar("T")
# PostgreSQL: lock_not_available, deadlock_detected, serialization_failure
_PG_BUSY = {"55P03", "40P01", "40001"}
_SQLITE_WAIT_MS = 30000  # the busy timeout every SQLite connection has (cloudsim.app)


def is_busy(exc: BaseException) -> bool:
    """Tell whether an error means "another transaction holds the lock: try again"."""
    if not isinstance(exc, OperationalError):
        return False
    code = getattr(exc.orig, "pgcode", None) or getattr(exc.orig, "sqlstate", None)
    text = str(exc.orig).lower()
    return code in _PG_BUSY or "database is locked" in text or "database table is locked" in text


def retry_busy(write: Callable[[], T], *, attempts: int = 6, first_wait: float = 0.05) -> T:
    """Run a short write in its own transaction, again (with jittered backoff) while the
    database is busy; raise the last error when it stays busy.

    SQLite gives up at once, whatever its busy timeout, when a transaction that read first
    wants to write after another wrote: only a new transaction can succeed.
    """
    wait = first_wait
    for attempt in range(1, attempts + 1):
        try:
            return write()
        except OperationalError as exc:
            if not is_busy(exc) or attempt == attempts:
                raise
            log.info("database busy (attempt %d of %d): retrying", attempt, attempts)
            time.sleep(wait * (1 + random.random()))
            wait = min(wait * 2, 1.0)
    raise AssertionError("unreachable")


def try_write(engine: Engine, statement: Executable, wait_ms: int = 200) -> bool:
    """Run a write that may be skipped (bookkeeping such as a token's last use): wait at most
    `wait_ms` for the lock, and return False instead of waiting longer or failing."""
    try:
        with engine.begin() as conn:
            if engine.dialect.name == "sqlite":
                conn.exec_driver_sql(f"PRAGMA busy_timeout={int(wait_ms)}")
                try:
                    conn.execute(statement)
                finally:
                    conn.exec_driver_sql(f"PRAGMA busy_timeout={_SQLITE_WAIT_MS}")
            else:
                conn.exec_driver_sql(f"SET LOCAL lock_timeout = '{int(wait_ms)}ms'")
                conn.execute(statement)
    except OperationalError as exc:
        if not is_busy(exc):
            raise
        log.info("skipped a bookkeeping write: the database is busy")
        return False
    return True
