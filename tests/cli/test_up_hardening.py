"""`cloudsim up`'s web server: gunicorn's own error answers carry the security headers, and
its control socket is the instance's own (two CloudSims on one machine never share one)."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from tests.support.servers import wait_for
from tests.support.up import cloudsim_up

HARDENING = ("Content-Security-Policy", "X-Frame-Options", "X-Content-Type-Options")


def _raw_get(port: int, target: str) -> bytes:
    """Send a GET with a request target of any length; return the whole answer."""
    with socket.create_connection(("127.0.0.1", port), timeout=180) as sock:  # a booting worker
        sock.sendall(f"GET {target} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".encode())
        chunks = []
        while chunk := sock.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


def test_gunicorn_answers_carry_the_headers_and_its_socket_is_the_instances(
    tmp_path: Path, pytestconfig: pytest.Config
) -> None:
    instance = tmp_path / "instance"
    settings = {"CLOUDSIM_WEB_WORKERS": "1", "CLOUDSIM_LOG_LEVEL": "WARNING"}
    with cloudsim_up(tmp_path, pytestconfig.rootpath, **settings) as up:
        port = int(up.address.rpartition(":")[2])
        wait_for((instance / "gunicorn.ctl").is_socket, 30, "gunicorn's control socket")
        answer = _raw_get(port, "/" + "a" * 10_000)  # over gunicorn's request-line limit
        head = answer.split(b"\r\n\r\n", 1)[0].decode("latin-1")
        assert head.startswith("HTTP/1.1 414"), head
        for header in HARDENING:
            assert f"\r\n{header}: " in head, head
        normal = _raw_get(port, "/login").split(b"\r\n\r\n", 1)[0].decode("latin-1")
        assert normal.startswith("HTTP/1.1 200") and "Content-Security-Policy" in normal
    assert not (instance / "gunicorn.ctl").exists()
