"""SSH key pairs for the servers provider tests."""

from __future__ import annotations

from dataclasses import dataclass, field

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.hazmat.primitives.serialization import (
    Encoding,
    NoEncryption,
    PrivateFormat,
    PublicFormat,
)


@dataclass(frozen=True)
class KeyPair:
    """An ed25519 key pair: OpenSSH private key text and public key line."""

    private: str = field(repr=False)
    public_line: str

    @property
    def blob(self) -> str:
        """Return the public key's base64 part."""
        return self.public_line.split()[1]


def make_key_pair(comment: str) -> KeyPair:
    """Generate an ed25519 key pair."""
    secret = Ed25519PrivateKey.generate()
    private = secret.private_bytes(Encoding.PEM, PrivateFormat.OpenSSH, NoEncryption()).decode()
    public = secret.public_key().public_bytes(Encoding.OpenSSH, PublicFormat.OpenSSH).decode()
    return KeyPair(private=private, public_line=f"{public} {comment}")
