"""Audit: the record of who did what, its page and API."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.audit import api, views

    app.register_blueprint(views.bp)
    register_api(app, api.blp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
