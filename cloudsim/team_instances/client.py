"""Calling a team instance's API: HTTPS only, its certificate pinned, the master's token.

The instance's certificate must chain to the deployment CA (kept by the master), name the
address called, and have exactly the fingerprint recorded when it was issued: a certificate
from anywhere else is refused before a byte of the request (or the token) is sent.
"""

from __future__ import annotations

import hashlib
import http.client
import json
import socket
import ssl
import subprocess
from dataclasses import dataclass, field
from typing import Any

from cloudsim.errors import CloudSimError


class InstanceError(CloudSimError):
    """A team instance could not be reached, was not who it should be, or refused a call."""

    status = 502


class CallRefused(InstanceError):
    """The other side answered with an error status (its code and JSON answer kept)."""

    def __init__(self, message: str, code: int, answer: Any) -> None:
        super().__init__(message)
        self.code = code
        self.answer = answer


class PinMismatch(InstanceError):
    """The instance's certificate is not the one the master pinned."""


@dataclass(frozen=True)
class Endpoint:
    """Where and how to call one instance."""

    host: str
    port: int
    ca_cert: str
    fingerprint: str  # SHA-256 of the certificate's DER, hex
    token: str = field(repr=False)
    # an argv connecting stdio to host:port (a provider's route from "the internet"), or None
    proxy: list[str] | None = None

    @property
    def url(self) -> str:
        """Return the instance's base URL."""
        return f"https://{self.host}:{self.port}/"


class _PinnedConnection(http.client.HTTPSConnection):
    """An HTTPS connection that checks the CA, the address and the pinned fingerprint."""

    def __init__(self, endpoint: Endpoint, timeout: float) -> None:
        context = ssl.create_default_context(cadata=endpoint.ca_cert)
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        super().__init__(endpoint.host, endpoint.port, timeout=timeout, context=context)
        self._endpoint = endpoint
        self._tls = context
        self._proxy: subprocess.Popen[bytes] | None = None

    def connect(self) -> None:
        if self._endpoint.proxy:
            ours, theirs = socket.socketpair()
            self._proxy = subprocess.Popen(
                self._endpoint.proxy,
                stdin=theirs.fileno(),
                stdout=theirs.fileno(),
                stderr=subprocess.DEVNULL,
            )
            theirs.close()
            ours.settimeout(self.timeout)
            raw = ours
        else:
            raw = socket.create_connection((self.host, self.port), self.timeout)
        try:
            tls = self._tls.wrap_socket(raw, server_hostname=self.host)
        except ssl.SSLCertVerificationError as exc:
            raw.close()
            raise PinMismatch(f"{self.host}: certificate refused ({exc.verify_message})") from None
        der = tls.getpeercert(binary_form=True) or b""
        if hashlib.sha256(der).hexdigest() != self._endpoint.fingerprint:
            tls.close()
            raise PinMismatch(f"{self.host}: certificate does not match the pinned one")
        self.sock = tls

    def release(self) -> None:
        """Close the connection and end its proxy, once the answer has been read.

        Not in close(): http.client closes the connection as soon as it has the headers of
        a `Connection: close` answer, and the proxy may still be relaying the body.
        """
        self.close()
        if self._proxy is not None:
            self._proxy.kill()
            self._proxy.wait()
            self._proxy = None


def call(
    endpoint: Endpoint,
    method: str,
    path: str,
    body: Any = None,
    timeout: float = 10,
    data: bytes | None = None,
) -> Any:
    """Call the other side's API (`path` under /api/v1) with a JSON `body` or raw `data`;
    return the JSON answer, raise otherwise (CallRefused for an error status)."""
    connection = _PinnedConnection(endpoint, timeout)
    headers = {"Authorization": f"Bearer {endpoint.token}", "Accept": "application/json"}
    payload = data
    if data is not None:
        headers["Content-Type"] = "application/octet-stream"
    elif body is not None:
        payload = json.dumps(body).encode()
        headers["Content-Type"] = "application/json"
    try:
        connection.request(method, f"/api/v1{path}", body=payload, headers=headers)
        response = connection.getresponse()
        data = response.read()
    except PinMismatch:
        raise
    except (OSError, http.client.HTTPException) as exc:
        raise InstanceError(f"{endpoint.host}:{endpoint.port} unreachable: {exc}") from None
    finally:
        connection.release()
    try:
        answer = json.loads(data) if data else None
    except ValueError:
        raise InstanceError(f"{endpoint.host}: answered {response.status} without JSON") from None
    if response.status >= 300:
        message = answer.get("message") if isinstance(answer, dict) else None
        raise CallRefused(
            f"{endpoint.host}: {method} {path} answered {response.status}: {message}",
            response.status,
            answer,
        )
    return answer
