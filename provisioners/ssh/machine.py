"""Where a machine is and how to log in to it."""

from __future__ import annotations

import io
from dataclasses import dataclass, field

import paramiko
from cryptography.exceptions import UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from cryptography.hazmat.primitives.asymmetric.types import PrivateKeyTypes

from provisioners.ssh.errors import ConnectError


@dataclass(frozen=True, kw_only=True)
class Machine:
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
    jump: Machine | None = None

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


_PARAMIKO_KEY_CLASSES: tuple[tuple[type, type[paramiko.PKey]], ...] = (
    (ed25519.Ed25519PrivateKey, paramiko.Ed25519Key),
    (ec.EllipticCurvePrivateKey, paramiko.ECDSAKey),
    (rsa.RSAPrivateKey, paramiko.RSAKey),
)


def load_private_key(machine_name: str, key_text: str) -> paramiko.PKey:
    """Parse a private key given as text (OpenSSH or PKCS#8 PEM) without touching disk."""
    data = key_text.encode()
    key: PrivateKeyTypes
    try:
        if b"OPENSSH PRIVATE KEY" in data:
            key = serialization.load_ssh_private_key(data, password=None)
        else:
            key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm) as exc:
        # the message never quotes the key text: it is a secret
        raise ConnectError(
            f"machine {machine_name!r}: private key is not an unencrypted OpenSSH/PEM key"
        ) from exc
    for crypto_class, paramiko_class in _PARAMIKO_KEY_CLASSES:
        if isinstance(key, crypto_class):
            # paramiko reads Ed25519 only from the OpenSSH container, so re-wrap in memory
            openssh = key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.OpenSSH,
                serialization.NoEncryption(),
            )
            return paramiko_class.from_private_key(io.StringIO(openssh.decode()))
    raise ConnectError(
        f"machine {machine_name!r}: unsupported private key type {type(key).__name__}"
    )
