"""Logs a machine can read: with CLOUDSIM_LOG_FORMAT=json, one JSON object a line.

Each line names the request, the user, and the job, run and constellation it is about, where
they apply, taken from the request (web server) or the job runner's log context (workers).
Secrets never reach a log line: requests are logged by path (never the query string, a body
or a header), and the job runner masks what its bodies log to the job row.
"""

from __future__ import annotations

import json
import logging
import re
import sys
import time
import uuid
from datetime import UTC, datetime
from typing import Any

from flask import Flask, Response, g, has_request_context, request
from gunicorn.glogging import Logger as GunicornLogger

from cloudsim import logcontext

REQUEST_ID = re.compile(r"[A-Za-z0-9._-]{1,64}")
access_log = logging.getLogger("cloudsim.access")
# Attributes every LogRecord has: the rest were passed with `extra=` and are shown.
_STANDARD = set(vars(logging.makeLogRecord({}))) | {"message", "asctime", "taskName"}


class JsonFormatter(logging.Formatter):
    """Format a record as one JSON object, with the ids of what it is about."""

    def format(self, record: logging.LogRecord) -> str:
        line: dict[str, Any] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        line.update(_request_ids())
        line.update(logcontext.current())
        for key, value in vars(record).items():
            if key not in _STANDARD and not key.startswith("_"):
                line[key] = value
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, default=str)


def _request_ids() -> dict[str, Any]:
    """Return the request's id and user, and the ids its route names (run, job, ...)."""
    if not has_request_context():
        return {}
    ids: dict[str, Any] = {}
    if "request_id" in g:
        ids["request_id"] = g.request_id
    # the API's caller, or flask-login's cached user: reading them never loads one (no query
    # inside logging)
    user = g.get("api_user") or g.get("_login_user")
    if user is not None and getattr(user, "is_authenticated", False):
        ids["user_id"] = user.id
    for key in logcontext.FIELDS:
        value = (request.view_args or {}).get(key)
        if value is not None:
            ids[key] = value
    return ids


def use_json_logs(level: str) -> None:
    """Send every log record of this process to stderr as JSON lines."""
    # the process's real stderr: Celery points sys.stderr at a proxy that logs what it gets
    handler = logging.StreamHandler(sys.__stderr__ or sys.stderr)
    handler.setFormatter(JsonFormatter())
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)
    logging.captureWarnings(True)  # Python's warnings (Celery's as root, ...) as JSON lines too
    cloudsim = logging.getLogger("cloudsim")
    for old in list(cloudsim.handlers):  # Flask's default handler on the app's logger
        cloudsim.removeHandler(old)
    cloudsim.propagate = True


def init_request_logs(app: Flask) -> None:
    """Give each request an id (X-Request-ID, kept from a proxy when sane); log it as JSON."""

    def name_request() -> None:
        given = request.headers.get("X-Request-ID", "")
        g.request_id = given if REQUEST_ID.fullmatch(given) else uuid.uuid4().hex
        g.request_started = time.perf_counter()

    # first of all: a request another hook refuses (the API's 401) is named and logged too
    app.before_request_funcs.setdefault(None, []).insert(0, name_request)

    @app.after_request
    def log_request(response: Response) -> Response:
        if "request_id" in g:
            response.headers["X-Request-ID"] = g.request_id
        if app.config["CLOUDSIM"].log_format == "json" and "request_started" in g:
            access_log.info(
                "%s %s %s",
                request.method,
                request.path,
                response.status_code,
                extra={
                    "method": request.method,
                    "path": request.path,  # never the query string: it may carry a secret
                    "status": response.status_code,
                    "duration_ms": round(1000 * (time.perf_counter() - g.request_started), 1),
                    "remote_addr": request.remote_addr,
                },
            )
        return response


class JsonGunicornLogger(GunicornLogger):  # type: ignore[misc]
    """gunicorn's own lines (start, workers, errors) as JSON too: `--logger-class` this."""

    def setup(self, cfg: Any) -> None:
        super().setup(cfg)
        for logger in (self.error_log, self.access_log):
            for handler in logger.handlers:
                handler.setFormatter(JsonFormatter())
