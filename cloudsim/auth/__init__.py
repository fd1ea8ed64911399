"""Auth: logging in and out, the caller's own account, API tokens and their bearer check."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's pages, API and jobs with the app."""
    from cloudsim.api import register_api
    from cloudsim.auth import api, views
    from cloudsim.auth.forms import ConfirmForm
    from cloudsim.auth.session import init_login

    init_login(app)
    api.init_bearer_auth(app)
    app.register_blueprint(views.bp)
    register_api(app, api.blp)
    app.jinja_env.globals.update(logout_form=ConfirmForm)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
