"""What a log line is about (job, run, constellation), carried in context variables.

The job runner binds them while a job's body runs; the JSON log format (cloudsim.monitoring)
adds them to every line. A plain module of the core, so the runner imports no feature.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

FIELDS = ("job_id", "run_id", "constellation_id")
_bound: ContextVar[dict[str, object] | None] = ContextVar("cloudsim_log_context", default=None)


@contextmanager
def bound(**ids: object) -> Iterator[None]:
    """Name what the lines logged inside the block are about (ids left None are not shown)."""
    current = dict(_bound.get() or {})
    current.update({key: value for key, value in ids.items() if value is not None})
    token = _bound.set(current)
    try:
        yield
    finally:
        _bound.reset(token)


def current() -> dict[str, object]:
    """Return the ids bound around the caller."""
    return dict(_bound.get() or {})


def about_target(target_type: str | None, target_id: int | None) -> dict[str, object]:
    """Return the log ids a job's target names (a run, a constellation), if any."""
    key = f"{target_type}_id"
    return {key: target_id} if key in FIELDS and target_id is not None else {}
