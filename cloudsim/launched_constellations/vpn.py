"""The team VPN of a constellation: its PKI (stored encrypted), users' bundles, revocation."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterable
from typing import Any

from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM, require_team_access
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations.access import (
    account_name,
    field_computers,
    refresh_team_access,
    ssh_config,
)
from cloudsim.launched_constellations.keys import constellation_secret
from cloudsim.models import Constellation, Role, Secret, SecretKind, User
from cloudsim.models.machines import GONE
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
    revocations = _revocations(constellation, ca)
    return VpnMaterial(
        ca_cert=ca.cert_pem,
        server_cert=server["cert"],
        server_key=server["key"],
        crl=revocations["crl"],
        revoked=tuple(revocations.get("names", [])),
    )


def client_certificate(constellation: Constellation, user: User) -> dict[str, Any]:
    """Return the user's certificate for this constellation's VPN, issuing it the first time."""
    ca = _ca(constellation)

    def issue() -> dict[str, Any]:
        _forgive(constellation, ca, user.email)
        return _issued_json(pki.issue_client(ca, user.email))

    return _pem_pair(constellation, f"{CLIENT_PREFIX}{user.id}", issue)


def _forgive(constellation: Constellation, ca: pki.CertificateAuthority, name: str) -> None:
    """Stop disconnecting a name that gets a new certificate (a user back on the team)."""
    before = _revocations(constellation, ca)
    if name in before.get("names", []):
        revoked = _revoked_row(constellation)
        revoked.value = json.dumps({**before, "names": sorted(set(before["names"]) - {name})})


def _revoked_row(constellation: Constellation) -> Secret:
    row = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == REVOKED,
        )
    )
    assert row is not None  # _revocations made it
    return row


def revoke_user(user: User, *, everywhere: bool = True) -> list[Constellation]:
    """Revoke the user's VPN certificates (everywhere, or where they are no longer an active
    member of the constellation's team); return the constellations to update."""
    member = user.active and user.role == Role.USER
    secrets = db.session.scalars(
        select(Secret).where(
            Secret.owner_type == "constellation", Secret.name == f"{CLIENT_PREFIX}{user.id}"
        )
    ).all()
    changed = []
    for secret in secrets:
        constellation = db.session.get(Constellation, secret.owner_id)
        if constellation is None or (
            not everywhere and member and constellation.team_id == user.team_id
        ):
            continue
        issued = json.loads(secret.value)
        revoke_certificate(constellation, int(issued["serial"]), issued["cn"])
        db.session.delete(secret)
        record(
            "vpn.revoke",
            SYSTEM,
            target_type="user",
            target_id=user.id,
            team_id=constellation.team_id,
            constellation=constellation.name,
            serial=int(issued["serial"]),
        )
        changed.append(constellation)
    return changed


def revoke_certificate(constellation: Constellation, serial: int, name: str) -> None:
    """Add a certificate to the constellation's revocation list (and its name to those the
    router disconnects)."""
    ca = _ca(constellation)
    before = _revocations(constellation, ca)
    if serial in before["serials"] and name in before.get("names", []):
        return  # a new CRL (new dates) for nothing would only churn the router
    serials = sorted({*before["serials"], serial})
    names = sorted({*before.get("names", []), name})
    _revoked_row(constellation).value = json.dumps(
        {**before, "serials": serials, "crl": pki.issue_crl(ca, serials), "names": names}
    )


def issue_check_certificate(constellation: Constellation, name: str) -> pki.IssuedCertificate:
    """Issue verification's own VPN client certificate, its serial recorded as one to revoke
    (the caller commits before the key is used: whatever dies, the serial is known)."""
    issued = pki.issue_client(_ca(constellation), name)
    before = _revocations(constellation, _ca(constellation))
    pending = [*before.get("pending", []), {"serial": issued.serial, "name": name}]
    _revoked_row(constellation).value = json.dumps({**before, "pending": pending})
    return issued


def pending_check_certificates(constellation: Constellation) -> list[tuple[int, str]]:
    """Return the (serial, name) of check certificates whose revocation the router may not
    have yet (none for a constellation without a VPN: nothing is made here)."""
    row = db.session.scalar(
        select(Secret).where(
            Secret.owner_type == "constellation",
            Secret.owner_id == constellation.id,
            Secret.name == REVOKED,
        )
    )
    if row is None:
        return []
    return [(int(p["serial"]), str(p["name"])) for p in json.loads(row.value).get("pending", [])]


def revoke_check_certificates(constellation: Constellation) -> list[int]:
    """Put every pending check certificate on the revocation list; return their serials.

    They stay pending until `forget_check_certificates`, once the router has the list.
    """
    revoked = []
    for serial, name in pending_check_certificates(constellation):
        revoke_certificate(constellation, serial, name)
        revoked.append(serial)
    return revoked


def forget_check_certificates(constellation: Constellation, serials: Iterable[int]) -> None:
    """Stop tracking check certificates the router now refuses (audited)."""
    gone = set(serials)
    before = _revocations(constellation, _ca(constellation))
    pending = [p for p in before.get("pending", []) if int(p["serial"]) not in gone]
    _revoked_row(constellation).value = json.dumps({**before, "pending": pending})
    for serial in sorted(gone):
        record(
            "vpn.check_revoked",
            SYSTEM,
            target_type="constellation",
            target_id=constellation.id,
            team_id=constellation.team_id,
            serial=serial,
        )


def client_config(constellation: Constellation, who: str, cert: str, key: str) -> str:
    """Return the .ovpn configuration of a client with this certificate and key."""
    return MachineTemplates().render(
        "router/client.ovpn.j2",
        {
            "user": who,
            "constellation": constellation.name,
            "file_name": _file_name(constellation, who),
            "remote_host": _router_address(constellation),
            "remote_port": VpnMaterial.port,
            "server_name": VPN_SERVER_NAME,
            "ca_cert": _ca(constellation).cert_pem,
            "client_cert": cert,
            "client_key": key,
        },
    )


def _router_address(constellation: Constellation) -> str:
    router = next((m for m in constellation.machines if m.role == "router"), None)
    if router is None or not router.public_ip:
        raise Conflict(f"{constellation.name} has no router address yet; wait until it is ready")
    return router.public_ip


def _file_name(constellation: Constellation, who: str) -> str:
    return f"{constellation.name}-{who.split('@')[0]}.ovpn"


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
    if constellation.state in GONE:
        raise Conflict(f"{constellation.name} is {constellation.state.value}")
    remote_host = _router_address(constellation)  # before a certificate is issued
    client = client_certificate(constellation, user)
    config = client_config(constellation, user.email, client["cert"], client["key"])
    file_name = _file_name(constellation, user.email)
    readme = MachineTemplates().render(
        "router/vpn-bundle-README.txt.j2",
        {
            "user": user.email,
            "constellation": constellation.name,
            "file_name": file_name,
            "remote_host": remote_host,
            "remote_port": VpnMaterial.port,
            "lan_addresses": {
                m.name: m.private_ip or "?" for m in constellation.machines if m.role != "router"
            },
            "field_computers": field_computers(constellation),
            "account": account_name(user, constellation),
            "ssh_config": ssh_config(constellation, user),
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


def revoke_and_push(user: User, team_ids: Iterable[int | None] = ()) -> None:
    """Revoke the user's VPN certificates and push access to the routers and field computers.

    The one hook for a user leaving (disabled, moved, deleted) or coming back: `team_ids` are
    the teams whose field computers' keys change (the old team and the new one).
    """
    revoked = revoke_user(user, everywhere=False)
    refresh_team_access([*team_ids, user.team_id], also=revoked)
