"""Team instances: the CloudSim a master deploys for each team, watched over pinned HTTPS
(service, state, health poll, pages, API, `cloudsim instance`), and the health endpoint
every CloudSim answers its master on."""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and periodic tasks with the app."""
    from cloudsim.api import register_api
    from cloudsim.jobs.queue import schedule_task
    from cloudsim.team_instances import api, health, poll, sync, views  # noqa: F401 (tasks)

    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    every = app.config["CLOUDSIM"].instance_poll_seconds
    schedule_task(app, "cloudsim.team_instances.poll", timedelta(seconds=every))
    schedule_task(
        app, "cloudsim.team_instances.heartbeat", timedelta(seconds=health.HEARTBEAT_SECONDS)
    )
    # an instance that answers again is caught up within about a second, not at the next poll
    schedule_task(app, poll.CATCH_UP_TASK, poll.CATCH_UP_EVERY)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command(
        "instance",
        "cloudsim.team_instances.cli:instance",
        "Deploy and watch team instances (a CloudSim per team, run from this master).",
    )
