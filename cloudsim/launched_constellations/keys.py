"""SSH key pairs the app makes for each constellation, stored encrypted."""

from __future__ import annotations

import json
import secrets
from collections.abc import Callable
from dataclasses import dataclass, field

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from sqlalchemy import select

from cloudsim.auth.tokens import TOKEN_PREFIX
from cloudsim.extensions import db
from cloudsim.models import Constellation, Secret, SecretKind
from provisioners.remote import pki

SSH_KEY_NAME = "ssh"
INSTANCE_ADMIN_PASSWORD = "cloudsim-admin-password"  # noqa: S105 (a name, not a secret)
INSTANCE_ADMIN_TOKEN = "cloudsim-admin-token"  # noqa: S105 (a name, not a secret)
INSTANCE_TLS = "cloudsim-tls"
DEPLOYMENT_CA = "cloudsim-instance-ca"  # the installation's CA for its CloudSim instances


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


def instance_admin_token(constellation: Constellation) -> str:
    """Return the API token the admin of a `cloudsim` constellation's CloudSim gets (made once)."""
    return constellation_secret(
        constellation,
        INSTANCE_ADMIN_TOKEN,
        SecretKind.CLOUD_CREDENTIALS,
        lambda: TOKEN_PREFIX + secrets.token_urlsafe(32),
    )


@dataclass(frozen=True)
class InstanceTls:
    """What a CloudSim instance serves HTTPS with, and what its master pins."""

    ca_cert: str
    cert: str
    key: str = field(repr=False)
    addresses: tuple[str, ...]
    fingerprint: str


def deployment_ca() -> pki.CertificateAuthority:
    """Return the CA this CloudSim signs its instances' HTTPS certificates with (made once)."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "installation", Secret.owner_id == 0, Secret.name == DEPLOYMENT_CA
        )
    )
    if secret is None:
        ca = pki.new_ca("CloudSim instances CA")
        secret = Secret(
            kind=SecretKind.VPN_KEY,
            owner_type="installation",
            owner_id=0,
            name=DEPLOYMENT_CA,
            value=json.dumps({"cert": ca.cert_pem, "key": ca.key_pem}),
        )
        db.session.add(secret)
        db.session.flush()
    stored = json.loads(secret.value)
    return pki.CertificateAuthority(stored["cert"], stored["key"])


def instance_tls(constellation: Constellation) -> InstanceTls:
    """Return the HTTPS certificate of a `cloudsim` constellation's public addresses.

    Issued by the deployment CA the first time, and again when the addresses changed (a
    replaced machine), so that the certificate always names the address the master calls.
    """
    addresses = tuple(sorted(m.public_ip for m in constellation.machines if m.public_ip))
    ca = deployment_ca()
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == INSTANCE_TLS,
        )
    )
    stored = json.loads(secret.value) if secret is not None else {}
    if tuple(stored.get("addresses", ())) != addresses or stored.get("ca") != ca.cert_pem:
        issued = pki.issue_tls_server(ca, f"cloudsim-{constellation.name}", addresses)
        stored = {"ca": ca.cert_pem, "cert": issued.cert_pem, "key": issued.key_pem}
        stored["addresses"] = list(addresses)
        if secret is None:
            secret = Secret(
                kind=SecretKind.VPN_KEY,
                owner_type="constellation",
                owner_id=constellation.id,
                name=INSTANCE_TLS,
                value="",
            )
            db.session.add(secret)
        secret.value = json.dumps(stored)
        db.session.flush()
    return InstanceTls(
        ca_cert=stored["ca"],
        cert=stored["cert"],
        key=stored["key"],
        addresses=tuple(stored["addresses"]),
        fingerprint=pki.certificate_fingerprint(stored["cert"]),
    )


def stored_instance_ca(constellation: Constellation) -> str | None:
    """Return the CA certificate a `cloudsim` constellation's HTTPS certificate chains to, once
    it has one (what a browser is told to trust), without making anything."""
    secret = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == INSTANCE_TLS,
        )
    )
    return str(json.loads(secret.value)["ca"]) if secret is not None else None
