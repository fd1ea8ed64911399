"""Flask-Login wiring for browser sessions (the API authenticates by token, see cloudsim.api)."""

from __future__ import annotations

from flask import Flask, redirect, request, url_for
from flask.typing import ResponseReturnValue

from cloudsim.extensions import db, login_manager
from cloudsim.models import User


def init_login(app: Flask) -> None:
    """Teach Flask-Login how to find the user of a browser session."""
    login_manager.login_view = "auth.login"
    login_manager.login_message = "Please log in to see that page."
    login_manager.session_protection = "strong"

    @login_manager.user_loader
    def load_user(session_id: str) -> User | None:
        # The id carries the session version: changing a password logs out old sessions.
        user_id, _, version = session_id.partition(":")
        if not user_id.isdigit() or not version.isdigit():
            return None
        user = db.session.get(User, int(user_id))
        if user is None or user.session_version != int(version) or not user.active:
            return None
        return user

    @login_manager.unauthorized_handler
    def unauthorized() -> ResponseReturnValue:
        return redirect(url_for("auth.login", next=request.full_path.rstrip("?")))
