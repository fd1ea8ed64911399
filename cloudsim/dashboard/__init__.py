"""Dashboard: each role's start page."""

from __future__ import annotations

import click
from flask import Flask


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.dashboard import views

    app.register_blueprint(views.bp)


def init_cli(cli: click.Group) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
