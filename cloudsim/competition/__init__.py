"""Competition: tasks, schedules, runs and their jobs, scores, the leaderboard (pages, API, CLI)."""

from __future__ import annotations

from datetime import timedelta
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.competition import api, demo, jobs, live, supervision, views  # noqa: F401
    from cloudsim.jobs.queue import schedule_task

    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    every = timedelta(seconds=app.config["CLOUDSIM"].run_supervise_seconds)
    schedule_task(app, "cloudsim.competition.supervise", every)
    live_every = timedelta(seconds=app.config["CLOUDSIM"].run_live_seconds)
    schedule_task(app, "cloudsim.competition.live", live_every)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    where = "cloudsim.competition.cli"
    cli.add_lazy_command("task", f"{where}:task", "Schedule, list and delete tasks.")
    cli.add_lazy_command(
        "schedule", f"{where}:schedule_group", "Import and export the season's schedule (YAML)."
    )
    cli.add_lazy_command("run", f"{where}:run", "Start, stop and look at runs.")
    cli.add_lazy_command("leaderboard", f"{where}:leaderboard", "Print the ranking of the teams.")
