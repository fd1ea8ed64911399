"""The control socket: one JSON request line in, one JSON answer line out, root only."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import socket
import struct
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from csrouter.errors import ControlError, DaemonUnavailable, RouterError

log = logging.getLogger("csrouter")
MAX_REQUEST_BYTES = 4096
REQUEST_TIMEOUT_SECONDS = 5.0

Handler = Callable[[dict[str, Any]], dict[str, Any]]


class ControlServer:
    """Serve control requests on a Unix socket in a thread of its own."""

    def __init__(self, path: str, handler: Handler) -> None:
        self.path = Path(path)
        self._handler = handler
        self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(self.path.parent, 0o700)
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        previous = os.umask(0o077)
        try:
            self._socket.bind(str(self.path))
        finally:
            os.umask(previous)
        os.chmod(self.path, 0o600)
        self._socket.listen(8)
        self._thread = threading.Thread(target=self._serve, name="control", daemon=True)

    def start(self) -> None:
        """Start answering requests."""
        self._thread.start()

    def close(self) -> None:
        """Stop listening and remove the socket file."""
        self._socket.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()

    def _serve(self) -> None:
        while True:
            try:
                connection, _ = self._socket.accept()
            except OSError:
                return  # closed
            with connection:
                try:
                    self._answer(connection)
                except OSError as exc:
                    log.warning("control connection failed: %s", exc)

    def _answer(self, connection: socket.socket) -> None:
        connection.settimeout(REQUEST_TIMEOUT_SECONDS)
        uid = _peer_uid(connection)
        if uid not in (0, os.getuid()):
            _send(connection, {"ok": False, "error": f"uid {uid} may not control csrouter"})
            return
        try:
            request = json.loads(_read_line(connection))
            if not isinstance(request, dict):
                raise ValueError("the request must be a JSON object")
            answer = {"ok": True, **self._handler(request)}
        except (ValueError, KeyError, TypeError, RouterError) as exc:
            answer = {"ok": False, "error": str(exc)}
        _send(connection, answer)


def request(path: str, message: dict[str, Any], timeout: float = 10.0) -> dict[str, Any]:
    """Send one request to the daemon and return its answer (without the "ok" flag)."""
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as connection:
            connection.settimeout(timeout)
            connection.connect(path)
            _send(connection, message)
            answer = json.loads(_read_line(connection))
    except (OSError, ValueError) as exc:
        raise DaemonUnavailable(f"the csrouter daemon does not answer on {path}: {exc}") from exc
    if not answer.pop("ok", False):
        raise ControlError(str(answer.get("error", "unknown error")))
    return dict(answer)


def _peer_uid(connection: socket.socket) -> int:
    credentials = connection.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12)
    _pid, uid, _gid = struct.unpack("3i", credentials)
    return int(uid)


def _read_line(connection: socket.socket) -> str:
    data = b""
    while not data.endswith(b"\n"):
        chunk = connection.recv(MAX_REQUEST_BYTES)
        if not chunk:
            break
        data += chunk
        if len(data) > 16 * MAX_REQUEST_BYTES:
            raise ValueError("message too long")
    if not data:
        raise ValueError("empty message")
    return data.decode()


def _send(connection: socket.socket, message: dict[str, Any]) -> None:
    connection.sendall(json.dumps(message).encode() + b"\n")
