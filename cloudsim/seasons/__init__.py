"""Seasons: the phases a competition runs in, their rules, and the tasks they make (API, CLI)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's page and API with the app."""
    from cloudsim.api import register_api
    from cloudsim.seasons import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: LazyGroup) -> None:
    """Add `cloudsim phase` to the command line."""
    cli.add_lazy_command(
        "phase", "cloudsim.seasons.cli:phase", "List, schedule and reveal the season's phases."
    )
