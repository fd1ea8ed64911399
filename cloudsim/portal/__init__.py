"""The portal: every team's runs, scores and logs in one place, the leaderboard, the figures."""

from __future__ import annotations

import click
from flask import Flask


def init_app(app: Flask) -> None:
    """Register this feature's pages with the app."""
    from cloudsim.portal import views

    app.register_blueprint(views.bp)


def init_cli(cli: click.Group) -> None:
    """The portal has no commands of its own (`cloudsim leaderboard` is the competition's)."""
