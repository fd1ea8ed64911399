"""Dashboard: each role's start page."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.dashboard import views

    app.register_blueprint(views.bp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
