"""Launched constellations: the machines a team gets (service, launch/terminate jobs, pages, API,
`cloudsim constellation`). What a constellation is made of (kinds, plans) is the top-level
`constellations` package."""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.jobs.queue import schedule_task
    from cloudsim.launched_constellations import (  # noqa: F401 (tasks)
        api,
        check_sweeper,
        jobs,
        reconcile,
        views,
    )

    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    schedule_task(app, "cloudsim.launched_constellations.reconcile", timedelta(minutes=5))
    schedule_task(app, "cloudsim.launched_constellations.sweep_vpn_checks", timedelta(minutes=1))


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command(
        "constellation",
        "cloudsim.launched_constellations.cli:constellation",
        "Launch, list, show and terminate constellations.",
    )
