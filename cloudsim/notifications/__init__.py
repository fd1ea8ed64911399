"""Notifications: run e-mails and signed webhook events when a run starts, ends or fails."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and tasks with the app."""
    from cloudsim.api import register_api
    from cloudsim.notifications import api, delivery, views

    del delivery  # imported so the worker knows its tasks
    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    app.add_template_global(views.run_emails_form)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command(
        "notify",
        "cloudsim.notifications.cli:notify",
        "Run notifications: send again what the queue missed.",
    )
