"""World definitions as data: the documents runs are built and scored from, stored here,
updated by admins (page, API, `cloudsim world`), handed to the simulator with every run and
propagated to team instances."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages and API with the app."""
    from cloudsim.api import register_api
    from cloudsim.worlds import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command(
        "world",
        "cloudsim.worlds.cli:world",
        "World definitions: run configurations and scoring rules, as data.",
    )
