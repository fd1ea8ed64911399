"""The portal: every team's runs, scores and logs in one place, the leaderboard, the figures;
uploads from team instances (the master's ingest, an instance's outbox), checked and reviewed."""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and periodic upload with the app."""
    from cloudsim.api import API_PREFIX, OWN_AUTH_PREFIXES, register_api
    from cloudsim.jobs.queue import schedule_task
    from cloudsim.portal import ingest_api, ingest_views, outbox, staging, views

    app.register_blueprint(views.bp)
    app.register_blueprint(ingest_views.bp)
    OWN_AUTH_PREFIXES.add(API_PREFIX + ingest_api.INGEST_PREFIX)
    register_api(app, ingest_api.ingest_blp)
    register_api(app, ingest_api.blp)
    every = app.config["CLOUDSIM"].portal_upload_seconds
    schedule_task(app, outbox.TASK, timedelta(seconds=every))
    schedule_task(app, outbox.PROBE_TASK, outbox.PROBE_EVERY)  # a master back: sent at once
    schedule_task(app, staging.TASK, staging.EVERY)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim` (`cloudsim leaderboard` is the competition's)."""
    cli.add_lazy_command(
        "portal",
        "cloudsim.portal.cli:portal",
        "The portal: where team instances upload their runs.",
    )
