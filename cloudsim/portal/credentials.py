"""Who may upload to the portal, and how an instance knows it is talking to its master.

On the master: each team instance gets an upload token (`cspu_<instance id>_<random>`, made
once, kept encrypted with the instance's other secrets) that only lets it add its own team's
results; the master's portal serves HTTPS with a certificate its instance CA issues for the
host of CLOUDSIM_PORTAL_URL. Both, with the CA and the certificate's SHA-256, reach the
instance in its desired state (over the master's pinned connection, with its admin token).

On the instance: those settings are kept encrypted (an installation secret) and the uploads
call the master only over HTTPS whose certificate chains to that CA, names the host, and has
exactly that SHA-256 (the pinned client of cloudsim.team_instances).
"""

from __future__ import annotations

import hmac
import json
import secrets
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import constellation_secret, deployment_ca
from cloudsim.models import InstanceState, Secret, SecretKind, TeamInstance
from cloudsim.team_instances.client import Endpoint
from provisioners.remote import pki

UPLOAD_TOKEN = "cloudsim-portal-upload-token"  # noqa: S105 (a name, not a secret)
UPLOAD_TOKEN_PREFIX = "cspu_"  # noqa: S105 (a marker, not a secret)
PORTAL_TLS = "cloudsim-portal-tls"  # the master's portal certificate (installation secret)
PORTAL_SETTINGS = "cloudsim-portal"  # on an instance: where and how to upload (installation)


def upload_token(instance: TeamInstance) -> str:
    """Return the instance's upload token (made the first time)."""
    return constellation_secret(
        instance.constellation,
        UPLOAD_TOKEN,
        SecretKind.CLOUD_CREDENTIALS,
        lambda: f"{UPLOAD_TOKEN_PREFIX}{instance.id}_{secrets.token_urlsafe(32)}",
    )


def instance_for_token(token: str) -> TeamInstance | None:
    """Return the (not terminated) instance an upload token belongs to, or None."""
    if not token.startswith(UPLOAD_TOKEN_PREFIX):
        return None
    number, _, rest = token[len(UPLOAD_TOKEN_PREFIX) :].partition("_")
    if not number.isdigit() or not rest or len(number) > 12:
        return None
    instance = db.session.get(TeamInstance, int(number))
    if instance is None or instance.state == InstanceState.TERMINATED:
        return None
    stored = db.session.scalar(
        select(Secret.value).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == instance.constellation_id,
            Secret.name == UPLOAD_TOKEN,
        )
    )
    if stored is None or not hmac.compare_digest(stored.encode(), token.encode()):
        return None
    return instance


@dataclass(frozen=True)
class PortalTls:
    """The certificate the master's portal serves, and what instances pin."""

    ca_cert: str
    cert: str
    key: str = field(repr=False)
    host: str
    fingerprint: str


def _installation_secret(name: str) -> Secret | None:
    return db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "installation", Secret.owner_id == 0, Secret.name == name
        )
    )


def portal_tls(config: Config) -> PortalTls | None:
    """Return the portal's certificate for CLOUDSIM_PORTAL_URL's host (issued by the instance
    CA the first time and whenever the host changes), or None when no portal URL is set."""
    if not config.portal_url:
        return None
    host = urlsplit(config.portal_url).hostname or ""
    ca = deployment_ca()
    secret = _installation_secret(PORTAL_TLS)
    stored = json.loads(secret.value) if secret is not None else {}
    if stored.get("host") != host or stored.get("ca") != ca.cert_pem:
        issued = pki.issue_tls_server(ca, "cloudsim-portal", (host,))
        stored = {"ca": ca.cert_pem, "cert": issued.cert_pem, "key": issued.key_pem, "host": host}
        if secret is None:
            secret = Secret(
                kind=SecretKind.VPN_KEY, owner_type="installation", owner_id=0, name=PORTAL_TLS
            )
            db.session.add(secret)
        secret.value = json.dumps(stored)
        db.session.flush()
    return PortalTls(
        ca_cert=stored["ca"],
        cert=stored["cert"],
        key=stored["key"],
        host=host,
        fingerprint=pki.certificate_fingerprint(stored["cert"]),
    )


def write_certificate(config: Config, folder: Path) -> tuple[Path, Path, PortalTls]:
    """Write the portal's certificate and key (0600) for the web server; return their paths
    and the certificate."""
    tls = portal_tls(config)
    if tls is None:
        raise ValueError("set CLOUDSIM_PORTAL_URL first: the certificate names its host")
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    cert, key = folder / "portal.crt", folder / "portal.key"
    for path, text in ((cert, tls.cert), (key, tls.key)):
        path.touch(mode=0o600)
        path.chmod(0o600)
        path.write_text(text)
    return cert, key, tls


def portal_settings(instance: TeamInstance, config: Config) -> dict[str, Any] | None:
    """Return what an instance needs to upload here (URL, CA, pin, its token), or None when
    this master has no portal URL or the instance serves no team."""
    tls = portal_tls(config)
    if tls is None or instance.team_id is None:
        return None
    return {
        "url": config.portal_url,
        "ca_cert": tls.ca_cert,
        "fingerprint": tls.fingerprint,
        "token": upload_token(instance),
    }


def stored_settings() -> dict[str, Any] | None:
    """On an instance: return the portal settings its master sent, or None."""
    secret = _installation_secret(PORTAL_SETTINGS)
    return json.loads(secret.value) if secret is not None else None  # type: ignore[no-any-return]


def store_settings(settings: dict[str, Any] | None) -> bool:
    """On an instance: keep the master's portal settings (encrypted); True if they changed."""
    secret = _installation_secret(PORTAL_SETTINGS)
    if settings is None:
        if secret is None:
            return False
        db.session.delete(secret)
        return True
    value = json.dumps(settings, sort_keys=True)
    if secret is not None and secret.value == value:
        return False
    if secret is None:
        secret = Secret(
            kind=SecretKind.CLOUD_CREDENTIALS,
            owner_type="installation",
            owner_id=0,
            name=PORTAL_SETTINGS,
        )
        db.session.add(secret)
    secret.value = value
    db.session.flush()
    return True


def portal_endpoint() -> Endpoint | None:
    """On an instance: return how to call the master's portal (pinned), or None."""
    settings = stored_settings()
    if settings is None:
        return None
    url = urlsplit(settings["url"])
    return Endpoint(
        host=url.hostname or "",
        port=url.port or 443,
        ca_cert=settings["ca_cert"],
        fingerprint=settings["fingerprint"],
        token=settings["token"],
    )
