"""Competition: tasks, schedules, runs and their jobs, scores, the leaderboard (pages, API, CLI)."""

from __future__ import annotations

from datetime import timedelta

import click
from flask import Flask


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


def init_cli(cli: click.Group) -> None:
    """Add this feature's commands to `cloudsim`."""
    from cloudsim.competition.cli import leaderboard, run, schedule_group, task

    for command in (task, schedule_group, run, leaderboard):
        cli.add_command(command)
