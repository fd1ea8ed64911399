"""SSH key pairs the app makes for each constellation, stored encrypted."""

from __future__ import annotations

import secrets
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


def constellation_keypair(constellation: Constellation) -> KeyPair:
    """Return the constellation's SSH key pair, making and storing it the first time."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == SSH_KEY_NAME,
        )
    )
    if secret is None:
        pair = generate_keypair(f"cloudsim-{constellation.name}")
        secret = Secret(
            kind=SecretKind.SSH_PRIVATE_KEY,
            owner_type="constellation",
            owner_id=constellation.id,
            name=SSH_KEY_NAME,
            value=pair.private,
        )
        db.session.add(secret)
        db.session.commit()
        return pair
    private = serialization.load_ssh_private_key(secret.value.encode(), password=None)
    public = (
        private.public_key()
        .public_bytes(serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH)
        .decode()
    )
    return KeyPair(secret.value, f"{public} cloudsim-{constellation.name}")


def instance_admin_password(constellation: Constellation) -> str:
    """Return the admin password of the CloudSim a `cloudsim` constellation runs (made once)."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == INSTANCE_ADMIN_PASSWORD,
        )
    )
    if secret is None:
        secret = Secret(
            kind=SecretKind.CLOUD_CREDENTIALS,
            owner_type="constellation",
            owner_id=constellation.id,
            name=INSTANCE_ADMIN_PASSWORD,
            value=secrets.token_urlsafe(18),
        )
        db.session.add(secret)
        db.session.commit()
    return secret.value
