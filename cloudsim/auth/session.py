"""Browser sessions: each login is a row on the server, named in the cookie by a random key.

The cookie never carries the account's id (ids are reused after a delete), and logging out,
changing the password, disabling or deleting the account removes the rows, so a copied
cookie stops working at once. The API authenticates by token instead (see cloudsim.api).
"""

from __future__ import annotations

import hashlib
import secrets
from datetime import timedelta

from flask import Flask, current_app, redirect, request, session, url_for
from flask.typing import ResponseReturnValue
from flask_login import login_user, logout_user
from sqlalchemy import delete, select
from sqlalchemy.orm import joinedload

from cloudsim.auth.master import awaiting_master, is_master_account
from cloudsim.extensions import db, login_manager
from cloudsim.models import LoginSession, User, utcnow

SESSION_KEY = "_user_id"  # where Flask-Login keeps what its user_loader receives


def _digest(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def _lifetime() -> timedelta:
    return timedelta(hours=current_app.config["CLOUDSIM"].session_hours)


def start_session(user: User) -> None:
    """Log the browser in as user with a new server-side session (the caller commits)."""
    key = secrets.token_urlsafe(32)
    # The user's sessions that outlived their lifetime go now, so the table does not grow.
    db.session.execute(
        delete(LoginSession).where(
            LoginSession.user_id == user.id, LoginSession.created_at < utcnow() - _lifetime()
        )
    )
    db.session.add(LoginSession(user=user, key_hash=_digest(key), address=request.remote_addr))
    login_user(user)
    session[SESSION_KEY] = key  # replaces the account id Flask-Login stored


def end_session() -> None:
    """Log this browser out and forget its session on the server (the caller commits)."""
    key = session.get(SESSION_KEY)
    if isinstance(key, str):
        db.session.execute(delete(LoginSession).where(LoginSession.key_hash == _digest(key)))
    logout_user()


def end_sessions(user: User) -> None:
    """End every browser session of the user, wherever it is (the caller commits)."""
    db.session.execute(delete(LoginSession).where(LoginSession.user_id == user.id))


def init_login(app: Flask) -> None:
    """Teach Flask-Login how to find the user of a browser session."""
    login_manager.login_view = "auth.login"
    login_manager.login_message = "Please log in to see that page."
    login_manager.session_protection = "strong"

    @login_manager.user_loader
    def load_user(key: str) -> User | None:
        if not isinstance(key, str) or not key:
            return None
        # Every page asks: one query for the session and its user.
        row = db.session.scalar(
            select(LoginSession)
            .where(LoginSession.key_hash == _digest(key))
            .options(joinedload(LoginSession.user))
        )
        if row is None or not row.user.active:
            return None
        if row.created_at + _lifetime() < utcnow():
            return None  # the server ends it even if the browser kept the cookie
        if not is_master_account(row.user) and awaiting_master():
            return None  # a restarted team instance: its accounts may be stale (auth.master)
        return row.user

    @login_manager.unauthorized_handler
    def unauthorized() -> ResponseReturnValue:
        return redirect(url_for("auth.login", next=request.full_path.rstrip("?")))
