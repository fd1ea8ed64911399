"""Jobs: the background work queue's rows, their runner, sweeper, pages and API."""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.jobs import api, diagnostics, runner, service, views  # noqa: F401 (tasks)
    from cloudsim.jobs.queue import schedule_task

    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    lease = app.config["CLOUDSIM"].job_lease_seconds
    schedule_task(app, "cloudsim.jobs.sweep", timedelta(seconds=max(5, lease // 2)))


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
