"""The team VPN of a constellation: its PKI (stored encrypted), users' bundles, revocation."""

from __future__ import annotations

import io
import json
import zipfile
from typing import Any

from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM, require_team_access
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import constellation_secret
from cloudsim.models import Constellation, ConstellationState, Role, Secret, SecretKind, User
from constellations.plans.base import VpnMaterial
from constellations.plans.router import VPN_SERVER_NAME
from provisioners.remote import pki
from provisioners.remote.operations import MachineTemplates

CA = "vpn-ca"
SERVER = "vpn-server"
REVOKED = "vpn-revoked"
CLIENT_PREFIX = "vpn-client:"


def _pem_pair(constellation: Constellation, name: str, make: Any) -> dict[str, Any]:
    return dict(
        json.loads(
            constellation_secret(
                constellation, name, SecretKind.VPN_KEY, lambda: json.dumps(make())
            )
        )
    )


def _ca(constellation: Constellation) -> pki.CertificateAuthority:
    stored = _pem_pair(constellation, CA, lambda: _ca_json(constellation))
    return pki.CertificateAuthority(stored["cert"], stored["key"])


def _ca_json(constellation: Constellation) -> dict[str, str]:
    ca = pki.new_ca(f"CloudSim VPN CA {constellation.name}")
    return {"cert": ca.cert_pem, "key": ca.key_pem}


def _issued_json(certificate: pki.IssuedCertificate) -> dict[str, Any]:
    return {
        "cert": certificate.cert_pem,
        "key": certificate.key_pem,
        "serial": certificate.serial,
        "cn": certificate.common_name,
    }


def _revocations(constellation: Constellation, ca: pki.CertificateAuthority) -> dict[str, Any]:
    """Return {"serials": [...], "crl": PEM}, made once and changed only by a revocation.

    The CRL text is kept, not reissued: a new one (new dates) would restart the VPN server.
    """
    return _pem_pair(constellation, REVOKED, lambda: {"serials": [], "crl": pki.issue_crl(ca, [])})


def server_material(constellation: Constellation) -> VpnMaterial:
    """Return what the router's VPN server needs, making the PKI the first time."""
    ca = _ca(constellation)
    server = _pem_pair(
        constellation, SERVER, lambda: _issued_json(pki.issue_server(ca, VPN_SERVER_NAME))
    )
    return VpnMaterial(
        ca_cert=ca.cert_pem,
        server_cert=server["cert"],
        server_key=server["key"],
        crl=_revocations(constellation, ca)["crl"],
    )


def client_certificate(constellation: Constellation, user: User) -> dict[str, Any]:
    """Return the user's certificate for this constellation's VPN, issuing it the first time."""
    ca = _ca(constellation)
    return _pem_pair(
        constellation,
        f"{CLIENT_PREFIX}{user.id}",
        lambda: _issued_json(pki.issue_client(ca, user.email)),
    )


def revoke_user(user: User) -> list[Constellation]:
    """Revoke the user's VPN certificates everywhere; return the constellations to update."""
    secrets = db.session.scalars(
        select(Secret).where(
            Secret.owner_type == "constellation", Secret.name == f"{CLIENT_PREFIX}{user.id}"
        )
    ).all()
    changed = []
    for secret in secrets:
        constellation = db.session.get(Constellation, secret.owner_id)
        if constellation is None:
            continue
        serial = int(json.loads(secret.value)["serial"])
        ca = _ca(constellation)
        serials = sorted({*_revocations(constellation, ca)["serials"], serial})
        revoked = db.session.scalar(
            select(Secret).where(
                Secret.owner_type == "constellation",
                Secret.owner_id == constellation.id,
                Secret.name == REVOKED,
            )
        )
        assert revoked is not None  # _revocations made it
        revoked.value = json.dumps({"serials": serials, "crl": pki.issue_crl(ca, serials)})
        db.session.delete(secret)
        record(
            "vpn.revoke",
            SYSTEM,
            target_type="user",
            target_id=user.id,
            team_id=constellation.team_id,
            constellation=constellation.name,
            serial=serial,
        )
        changed.append(constellation)
    return changed


def vpn_bundle(
    actor: User, constellation: Constellation, user_id: int | None = None
) -> tuple[str, bytes]:
    """Return (file name, zip) of a team user's VPN bundle: their own, or (officers) anyone's.

    A bundle never holds SSH keys or the router's keys: only the CA certificate and the user's
    own certificate and key.
    """
    require_team_access(actor, constellation.team_id, "constellation", constellation.id)
    if user_id is not None and user_id != actor.id and not actor.has_role(Role.OFFICER):
        # The same answer whether or not the user exists: ids must not be probed through this.
        raise NotFound.of("user", user_id)
    user = actor if user_id is None else db.session.get(User, user_id)
    if user is None:
        raise NotFound.of("user", user_id)
    if user.role != Role.USER or user.team_id != constellation.team_id or not user.active:
        raise InvalidInput(f"{user.email} is not an active member of this constellation's team")
    if constellation.kind != "vrc":
        raise InvalidInput(
            f"{constellation.name} is a {constellation.kind} constellation: "
            "only vrc constellations have a team VPN"
        )
    if constellation.state in (ConstellationState.TERMINATING, ConstellationState.TERMINATED):
        raise Conflict(f"{constellation.name} is {constellation.state.value}")
    router = next((m for m in constellation.machines if m.role == "router"), None)
    if router is None or not router.public_ip:
        raise Conflict(f"{constellation.name} has no router address yet; wait until it is ready")
    ca_cert = _ca(constellation).cert_pem
    client = client_certificate(constellation, user)
    file_name = f"{constellation.name}-{user.email.split('@')[0]}.ovpn"
    templates = MachineTemplates()
    common = {
        "user": user.email,
        "constellation": constellation.name,
        "file_name": file_name,
        "remote_host": router.public_ip,
        "remote_port": VpnMaterial.port,
    }
    config = templates.render(
        "router/client.ovpn.j2",
        {
            **common,
            "server_name": VPN_SERVER_NAME,
            "ca_cert": ca_cert,
            "client_cert": client["cert"],
            "client_key": client["key"],
        },
    )
    readme = templates.render(
        "router/vpn-bundle-README.txt.j2",
        {
            **common,
            "lan_addresses": {
                m.name: m.private_ip or "?" for m in constellation.machines if m.role != "router"
            },
        },
    )
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as bundle:
        info = zipfile.ZipInfo(file_name)
        info.external_attr = 0o600 << 16
        bundle.writestr(info, config)
        bundle.writestr("README.txt", readme)
    record(
        "vpn.bundle",
        actor,
        target_type="constellation",
        target_id=constellation.id,
        team_id=constellation.team_id,
        user=user.email,
    )
    return f"{constellation.name}-vpn-{user.email.split('@')[0]}.zip", buffer.getvalue()


def revoke_and_push(user: User) -> None:
    """Revoke the user's VPN certificates and push the new revocation lists to the routers."""
    from cloudsim.launched_constellations import lifecycle

    for constellation in revoke_user(user):
        lifecycle.start_refresh_vpn(SYSTEM, constellation)
