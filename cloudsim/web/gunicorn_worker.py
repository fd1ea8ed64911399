"""The web server's worker: gunicorn's threaded worker whose own error answers carry the app's
security headers.

gunicorn answers some requests before Flask sees them (a request line over its limit: 414, a
malformed request: 400); those answers come from `gunicorn.util.write_error`, which sends no
security header. This worker sends them with the headers flask-talisman gives every other
answer. `cloudsim up` runs it: `--worker-class cloudsim.web.gunicorn_worker.SecureThreadWorker`.
"""

from __future__ import annotations

import html
import socket

from gunicorn import util
from gunicorn.workers.gthread import ThreadWorker

from cloudsim.web.security import CONTENT_SECURITY_POLICY

ERROR_HEADERS = {
    "Content-Security-Policy": "; ".join(f"{k} {v}" for k, v in CONTENT_SECURITY_POLICY.items()),
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "same-origin",
    "Cache-Control": "no-store",
}


def error_answer(status: int, reason: str, message: str) -> bytes:
    """Return the bytes of gunicorn's error answer, with the security headers."""
    body = (
        f"<html><head><title>{html.escape(reason)}</title></head>"
        f"<body><h1>{html.escape(reason)}</h1><p>{html.escape(message)}</p></body></html>"
    ).encode()
    lines = [
        f"HTTP/1.1 {status} {reason}",
        "Connection: close",
        "Content-Type: text/html; charset=utf-8",
        f"Content-Length: {len(body)}",
        *(f"{name}: {value}" for name, value in ERROR_HEADERS.items()),
    ]
    return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body


def write_error(sock: socket.socket, status_int: int, reason: str, mesg: str) -> None:
    """Send gunicorn's error answer with the security headers (util.write_error's signature)."""
    util.write_nonblock(sock, error_answer(status_int, reason, mesg))


class SecureThreadWorker(ThreadWorker):  # type: ignore[misc]
    """gunicorn's gthread worker, its own error answers hardened like the app's."""

    def init_process(self) -> None:
        # In the worker process only: gunicorn's handle_error looks write_error up per call.
        util.write_error = write_error
        super().init_process()
