"""The master's client refuses every certificate but the pinned one, before sending its token."""

from __future__ import annotations

import json
import ssl
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from cloudsim.team_instances.client import Endpoint, InstanceError, PinMismatch, call
from provisioners.remote import pki

TOKEN = "cst_test-token"


class _Health(BaseHTTPRequestHandler):
    seen: list[str | None] = []

    def do_GET(self) -> None:
        _Health.seen.append(self.headers.get("Authorization"))
        body = json.dumps({"version": "test", "database": True}).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Connection", "close")
        self.end_headers()
        # headers and body apart, as gunicorn sends them: the client must wait for the body
        # (through a proxy, too) even though it closes the connection once it has the headers
        self.wfile.flush()
        time.sleep(0.2)
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        return None


def _serve(cert: pki.IssuedCertificate, folder: Path) -> Iterator[int]:
    (folder / "cert.pem").write_text(cert.cert_pem)
    (folder / "key.pem").write_text(cert.key_pem)
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(folder / "cert.pem", folder / "key.pem")
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Health)
    server.socket = context.wrap_socket(server.socket, server_side=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module")
def ca() -> pki.CertificateAuthority:
    return pki.new_ca("test deployment CA")


@pytest.fixture(scope="module")
def good(ca: pki.CertificateAuthority) -> pki.IssuedCertificate:
    return pki.issue_tls_server(ca, "instance", ["127.0.0.1"])


def _endpoint(
    port: int, ca: pki.CertificateAuthority, pin: str, proxy: list[str] | None = None
) -> Endpoint:
    return Endpoint("127.0.0.1", port, ca.cert_pem, pin, TOKEN, proxy)


@pytest.mark.parametrize("through_proxy", [False, True])
def test_the_pinned_certificate_is_accepted(
    ca: pki.CertificateAuthority,
    good: pki.IssuedCertificate,
    tmp_path: Path,
    through_proxy: bool,
) -> None:
    for port in _serve(good, tmp_path):
        proxy = ["socat", "STDIO", f"TCP:127.0.0.1:{port}"] if through_proxy else None
        pin = pki.certificate_fingerprint(good.cert_pem)
        assert call(_endpoint(port, ca, pin, proxy), "GET", "/instance/health") == {
            "version": "test",
            "database": True,
        }
        assert _Health.seen[-1] == f"Bearer {TOKEN}"


@pytest.mark.parametrize("impostor", ["same CA, another certificate", "another CA", "wrong name"])
def test_any_other_certificate_is_refused_before_the_token_is_sent(
    ca: pki.CertificateAuthority, good: pki.IssuedCertificate, tmp_path: Path, impostor: str
) -> None:
    if impostor == "same CA, another certificate":
        served = pki.issue_tls_server(ca, "instance", ["127.0.0.1"])
    elif impostor == "another CA":
        served = pki.issue_tls_server(pki.new_ca("evil CA"), "instance", ["127.0.0.1"])
    else:
        served = pki.issue_tls_server(ca, "instance", ["192.0.2.1"])
    # the pin is the good certificate's unless the served one would pass every other check
    pin = pki.certificate_fingerprint(
        served.cert_pem if impostor == "wrong name" else good.cert_pem
    )
    seen = len(_Health.seen)
    for port in _serve(served, tmp_path):
        with pytest.raises(PinMismatch):
            call(_endpoint(port, ca, pin), "GET", "/instance/health")
    assert len(_Health.seen) == seen  # no request (and no token) reached the impostor


def test_nothing_listening_is_unreachable(ca: pki.CertificateAuthority) -> None:
    with pytest.raises(InstanceError, match="unreachable"):
        call(_endpoint(1, ca, "00"), "GET", "/instance/health", timeout=2)
