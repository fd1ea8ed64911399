"""People: teams and users (pages, API, `cloudsim team` and `cloudsim user`)."""

from __future__ import annotations

import click
from flask import Flask


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.people import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: click.Group) -> None:
    """Add this feature's commands to `cloudsim`."""
    from cloudsim.people.cli import team, user

    cli.add_command(team)
    cli.add_command(user)
