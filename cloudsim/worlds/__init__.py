"""World definitions as data: the documents runs are built and scored from, stored here,
updated by admins (page, API, `cloudsim world`), handed to the simulator with every run and
propagated to team instances."""

from __future__ import annotations

import click
from flask import Flask


def init_app(app: Flask) -> None:
    """Register this feature's pages and API with the app."""
    from cloudsim.api import register_api
    from cloudsim.worlds import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: click.Group) -> None:
    """Add this feature's commands to `cloudsim`."""
    from cloudsim.worlds.cli import world

    cli.add_command(world)
