"""Verification: every finished run re-simulated from its own logs before it is trusted.

A run is `verifying` (queued or under way), `verified`, `held` for review (with the reason)
or `accepted` by an officer after being held; a held run is not ranked.
"""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

SWEEP_EVERY = timedelta(seconds=10)


def init_app(app: Flask) -> None:
    """Register the verification job and the beat that queues finished runs."""
    from cloudsim.jobs.queue import schedule_task
    from cloudsim.verification import jobs, service  # noqa: F401 (the job and the beat's task)

    schedule_task(app, service.SWEEP, SWEEP_EVERY)


def init_cli(cli: object) -> None:
    """Add this feature's commands to `cloudsim`: none (the workers replay, not the CLI)."""
    del cli
