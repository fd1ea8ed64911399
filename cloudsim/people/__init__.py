"""People: teams and users (pages, API, `cloudsim team` and `cloudsim user`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.people import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command("team", "cloudsim.people.cli:team", "Create and list teams.")
    cli.add_lazy_command("user", "cloudsim.people.cli:user", "Create, list and change users.")
