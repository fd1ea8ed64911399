"""Where a machine is and how to log in to it."""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from typing import Any

import paramiko
from cryptography.exceptions import UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from cryptography.hazmat.primitives.asymmetric.types import PrivateKeyTypes

from provisioners.remote.ssh.errors import ConnectError


@dataclass(frozen=True, kw_only=True)
class SSHTarget:
    """An SSH target: address, login, key and how the controller's packets reach it."""

    name: str
    host: str
    private_key: str = field(repr=False)
    user: str = "root"
    port: int = 22
    # argv of a program that carries the SSH stream on its stdin/stdout, e.g. an
    # `ip netns exec` or socat bridge into a host living in a network namespace.
    proxy_command: list[str] | None = None
    # a machine that forwards our connection (direct-tcpip), e.g. a router in front of a LAN.
    jump: SSHTarget | None = None

    def __post_init__(self) -> None:
        if self.proxy_command is not None and self.jump is not None:
            raise ValueError(f"machine {self.name!r}: give proxy_command or jump, not both")
        if self.proxy_command is not None and not self.proxy_command:
            raise ValueError(f"machine {self.name!r}: proxy_command is an empty argv")
        if self.jump is not None and self.jump.name == self.name:
            raise ValueError(f"machine {self.name!r} cannot be its own jump machine")

    @property
    def address(self) -> str:
        """Return user@host:port for messages."""
        return f"{self.user}@{self.host}:{self.port}"


@dataclass(frozen=True, kw_only=True)
class Route:
    """How the controller reaches a machine, without its key: what a machine's row stores.

    `jump` names another machine of the same group to go through (a cloud's private
    machines are reached through the public one); `proxy_command` carries the stream itself.
    """

    host: str
    user: str = "root"
    port: int = 22
    proxy_command: tuple[str, ...] | None = None
    jump: str | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the route as plain JSON data."""
        return {
            "host": self.host,
            "user": self.user,
            "port": self.port,
            "proxy_command": list(self.proxy_command) if self.proxy_command else None,
            "jump": self.jump,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Route:
        """Rebuild a route saved by to_json."""
        proxy = data.get("proxy_command")
        return cls(
            host=str(data["host"]),
            user=str(data.get("user") or "root"),
            port=int(data.get("port") or 22),
            proxy_command=tuple(proxy) if proxy else None,
            jump=data.get("jump"),
        )

    def target(self, name: str, private_key: str, jump: SSHTarget | None = None) -> SSHTarget:
        """Return the SSH target this route leads to (jump: the target of `self.jump`)."""
        return SSHTarget(
            name=name,
            host=self.host,
            user=self.user,
            port=self.port,
            private_key=private_key,
            proxy_command=list(self.proxy_command) if self.proxy_command else None,
            jump=jump,
        )


_PARAMIKO_KEY_CLASSES: tuple[tuple[type, type[paramiko.PKey]], ...] = (
    (ed25519.Ed25519PrivateKey, paramiko.Ed25519Key),
    (ec.EllipticCurvePrivateKey, paramiko.ECDSAKey),
    (rsa.RSAPrivateKey, paramiko.RSAKey),
)


def openssh_private_key(machine_name: str, key_text: str) -> bytes:
    """Return a private key given as text (OpenSSH or PKCS#8 PEM) in OpenSSH's own format."""
    return _private_bytes(_parse_private_key(machine_name, key_text))


def load_private_key(machine_name: str, key_text: str) -> paramiko.PKey:
    """Parse a private key given as text (OpenSSH or PKCS#8 PEM) without touching disk."""
    key = _parse_private_key(machine_name, key_text)
    for crypto_class, paramiko_class in _PARAMIKO_KEY_CLASSES:
        if isinstance(key, crypto_class):
            # paramiko reads Ed25519 only from the OpenSSH container, so re-wrap in memory
            openssh = _private_bytes(key)
            return paramiko_class.from_private_key(io.StringIO(openssh.decode()))
    raise ConnectError(
        f"machine {machine_name!r}: unsupported private key type {type(key).__name__}"
    )


def _parse_private_key(machine_name: str, key_text: str) -> PrivateKeyTypes:
    data = key_text.encode()
    try:
        if b"OPENSSH PRIVATE KEY" in data:
            return serialization.load_ssh_private_key(data, password=None)
        return serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm) as exc:
        # the message never quotes the key text: it is a secret
        raise ConnectError(
            f"machine {machine_name!r}: private key is not an unencrypted OpenSSH/PEM key"
        ) from exc


def _private_bytes(key: PrivateKeyTypes) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.OpenSSH,
        serialization.NoEncryption(),
    )
