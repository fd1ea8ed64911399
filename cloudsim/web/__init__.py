"""The browser shell: error pages and template helpers; features add their blueprints."""

from __future__ import annotations

import base64
from datetime import datetime

from flask import Flask, Response, current_app, render_template, request
from flask.typing import ResponseReturnValue
from flask_wtf.csrf import CSRFError
from markupsafe import escape
from werkzeug.exceptions import HTTPException

from cloudsim import __version__
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Role

MESSAGES = {
    400: "The request was not understood.",
    401: "Please log in.",
    403: "You may not see or do that.",
    404: "There is nothing here.",
    405: "That action is not allowed here.",
    413: "That upload is too large.",
    429: "Too many attempts. Wait a minute and try again.",
    500: "Something went wrong on our side. It has been logged.",
}


def register_web(app: Flask) -> None:
    """Register the error pages and the template globals every page uses."""
    app.jinja_env.globals.update(Role=Role, cloudsim_version=__version__)
    app.jinja_env.filters["datetime"] = format_datetime
    app.jinja_env.filters["b64encode"] = _b64encode

    @app.after_request
    def end_transaction(response: Response) -> Response:
        # A request is a transaction boundary: a success commits what it changed, once, here.
        # A refusal commits nothing, whether an error handler below drew it or the view itself
        # showed its form again with the service's error (a view whose service may have failed
        # a flush still rolls back itself first: drawing the page reads the database).
        if response.status_code < 400:
            db.session.commit()
        else:
            db.session.rollback()
        return response

    @app.errorhandler(CloudSimError)
    def service_error(exc: CloudSimError) -> ResponseReturnValue:
        _rollback()
        return _error_page(exc.status, str(exc))

    @app.errorhandler(CSRFError)
    def csrf_error(exc: CSRFError) -> ResponseReturnValue:
        _rollback()
        return _error_page(400, "The form expired or was not sent by CloudSim. Reload and retry.")

    @app.errorhandler(HTTPException)
    def http_error(exc: HTTPException) -> ResponseReturnValue:
        _rollback()
        # webargs answers 422 for invalid fields; to callers it is a plain bad request.
        code = 400 if exc.code == 422 else exc.code or 500
        # Validation errors of the API carry the message of every bad field.
        fields = (getattr(exc, "data", None) or {}).get("messages")
        message = "invalid input" if fields else MESSAGES.get(code, exc.description or "")
        if code == 400 and exc.description and not fields:
            message = exc.description
        return _error_page(code, message, fields)

    @app.errorhandler(Exception)
    def crash(exc: Exception) -> ResponseReturnValue:
        app.logger.exception("unhandled error on %s %s", request.method, request.path)
        _rollback()
        return _error_page(500, MESSAGES[500])


def format_datetime(value: datetime | None, seconds: bool = False) -> str:
    """Show a UTC timestamp compactly; a dash when there is none."""
    if value is None:
        return "—"
    return value.strftime("%Y-%m-%d %H:%M:%S" if seconds else "%Y-%m-%d %H:%M")


def _rollback() -> None:
    """Undo the failed request's changes; a broken database must not break the error page."""
    try:
        db.session.rollback()
    except Exception:  # the original error is what gets reported
        current_app.logger.warning("rollback failed while answering an error", exc_info=True)


def _b64encode(text: str) -> str:
    """Return text as base64 (for data: links, e.g. a key shown once)."""
    return base64.b64encode(text.encode()).decode()


def _error_page(status: int, message: str, fields: object = None) -> ResponseReturnValue:
    """Answer an error as JSON (API) or a page; this path must never raise itself."""
    if request.path.startswith("/api/"):
        body: dict[str, object] = {"code": status, "message": message}
        if fields:
            body["errors"] = fields
        return body, status
    try:
        return render_template("error.html", status=status, message=message), status
    except Exception:
        # The page needs the session and the database; when they are the problem, answer plainly.
        current_app.logger.exception("the error page for %s could not be drawn", status)
        text = f"<!doctype html><title>{status}</title><h1>{status}</h1><p>{escape(message)}</p>"
        return text, status, {"Content-Type": "text/html; charset=utf-8"}
