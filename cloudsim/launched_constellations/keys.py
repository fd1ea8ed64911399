"""SSH key pairs the app makes for each constellation, stored encrypted."""

from __future__ import annotations

import secrets
from collections.abc import Callable
from dataclasses import dataclass

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from sqlalchemy import select

from cloudsim.extensions import db
from cloudsim.models import Constellation, Secret, SecretKind

SSH_KEY_NAME = "ssh"
INSTANCE_ADMIN_PASSWORD = "cloudsim-admin-password"  # noqa: S105 (a name, not a secret)


@dataclass(frozen=True)
class KeyPair:
    """An OpenSSH private key (PEM text) and its public line."""

    private: str
    public: str

    def __repr__(self) -> str:
        return f"KeyPair(public={self.public!r})"


def generate_keypair(comment: str) -> KeyPair:
    """Return a new ed25519 key pair."""
    key = Ed25519PrivateKey.generate()
    private = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.OpenSSH,
        serialization.NoEncryption(),
    ).decode()
    public = (
        key.public_key()
        .public_bytes(serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH)
        .decode()
    )
    return KeyPair(private, f"{public} {comment}")


def constellation_secret(
    constellation: Constellation, name: str, kind: SecretKind, make: Callable[[], str]
) -> str:
    """Return a secret of the constellation, making (with `make`) and storing it the first time."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == name,
        )
    )
    if secret is None:
        secret = Secret(
            kind=kind,
            owner_type="constellation",
            owner_id=constellation.id,
            name=name,
            value=make(),
        )
        db.session.add(secret)
        db.session.flush()  # the caller's boundary commits it with the rest
    return secret.value


def constellation_keypair(constellation: Constellation) -> KeyPair:
    """Return the constellation's SSH key pair, making and storing it the first time."""
    comment = f"cloudsim-{constellation.name}"
    private_text = constellation_secret(
        constellation,
        SSH_KEY_NAME,
        SecretKind.SSH_PRIVATE_KEY,
        lambda: generate_keypair(comment).private,
    )
    private = serialization.load_ssh_private_key(private_text.encode(), password=None)
    public = (
        private.public_key()
        .public_bytes(serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH)
        .decode()
    )
    return KeyPair(private_text, f"{public} {comment}")


def instance_admin_password(constellation: Constellation) -> str:
    """Return the admin password of the CloudSim a `cloudsim` constellation runs (made once)."""
    return constellation_secret(
        constellation,
        INSTANCE_ADMIN_PASSWORD,
        SecretKind.CLOUD_CREDENTIALS,
        lambda: secrets.token_urlsafe(18),
    )
