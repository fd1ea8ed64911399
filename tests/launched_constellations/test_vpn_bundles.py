"""Team VPN bundles: who gets which, what is inside, and revocation (no hosts needed)."""

from __future__ import annotations

import io
import zipfile

import pytest
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations import vpn
from cloudsim.models import (
    AuditEvent,
    Constellation,
    ConstellationState,
    Job,
    Machine,
    Role,
    User,
)
from cloudsim.people.service import delete_user
from provisioners.remote import pki
from tests.conftest import make_user, token_for


@pytest.fixture
def ready_vrc(app: Flask, people: dict[str, User | None]) -> Constellation:
    team = people["user_a"].team  # type: ignore[union-attr]
    constellation = Constellation(
        name="vrc-a", kind="vrc", provider="local", team_id=team.id, state=ConstellationState.READY
    )
    for n, role in enumerate(("router", "sim", "fc1", "fc2")):
        constellation.machines.append(
            Machine(name=role, role=role, private_ip=f"10.211.3.{50 + n}")
        )
    constellation.machines[0].public_ip = "198.18.0.7"
    db.session.add(constellation)
    db.session.commit()
    return constellation


def _files(bundle: bytes) -> dict[str, str]:
    archive = zipfile.ZipFile(io.BytesIO(bundle))
    return {name: archive.read(name).decode() for name in archive.namelist()}


def test_a_user_bundle_holds_only_their_own_vpn_identity(
    app: Flask, people: dict[str, User | None], ready_vrc: Constellation
) -> None:
    user = people["user_a"]
    name, data = vpn.vpn_bundle(user, ready_vrc)  # type: ignore[arg-type]
    files = _files(data)
    local_part = user.email.split("@")[0]  # type: ignore[union-attr]
    assert name == f"vrc-a-vpn-{local_part}.zip"
    assert sorted(files) == ["README.txt", f"vrc-a-{local_part}.ovpn"]
    config = next(text for file, text in files.items() if file.endswith(".ovpn"))
    assert "remote 198.18.0.7 1194" in config and "verify-x509-name cloudsim-router" in config
    assert "OPENSSH PRIVATE KEY" not in config  # never an SSH key
    material = vpn.server_material(ready_vrc)
    assert material.server_key.strip() not in config  # never the router's key
    client = vpn.client_certificate(ready_vrc, user)  # type: ignore[arg-type]
    assert client["cert"].strip() in config and client["key"].strip() in config
    assert pki.certificate_common_name(client["cert"]) == user.email  # type: ignore[union-attr]
    assert "10.211.3.51" in files["README.txt"]  # where sim is, once connected
    assert db.session.scalar(select(AuditEvent).where(AuditEvent.action == "vpn.bundle"))


def test_who_may_download_which_bundle(
    app: Flask, people: dict[str, User | None], ready_vrc: Constellation
) -> None:
    teammate = make_user(Role.USER, people["user_a"].team)  # type: ignore[union-attr]
    with pytest.raises(NotFound):  # as for an id that does not exist: ids are not probed
        vpn.vpn_bundle(people["user_a"], ready_vrc, teammate.id)  # type: ignore[arg-type]
    with pytest.raises(NotFound):
        vpn.vpn_bundle(people["user_b"], ready_vrc)  # type: ignore[arg-type]
    name, _ = vpn.vpn_bundle(people["officer"], ready_vrc, teammate.id)  # type: ignore[arg-type]
    assert teammate.email.split("@")[0] in name
    response = app.test_client().get(
        f"/api/v1/constellations/{ready_vrc.id}/vpn-bundle", headers=token_for(people["user_a"])
    )  # type: ignore[arg-type]
    assert response.status_code == 200 and response.mimetype == "application/zip"
    assert response.headers["Cache-Control"] == "no-store"


def test_removing_a_user_revokes_their_certificate_and_updates_the_router(
    app: Flask, people: dict[str, User | None], ready_vrc: Constellation
) -> None:
    user = people["user_a"]
    vpn.vpn_bundle(user, ready_vrc)  # type: ignore[arg-type]
    serial = vpn.client_certificate(ready_vrc, user)["serial"]  # type: ignore[arg-type]
    before = vpn.server_material(ready_vrc).crl
    assert vpn.server_material(ready_vrc).crl == before  # unchanged: no needless VPN restart
    delete_user(SYSTEM, user.id)  # type: ignore[union-attr]
    after = vpn.server_material(ready_vrc)
    ca = pki.CertificateAuthority(after.ca_cert, vpn._ca(ready_vrc).key_pem)
    assert serial in pki.revoked_serials(after.crl, ca)
    job = db.session.scalar(select(Job).where(Job.kind == "constellation.refresh_access"))
    assert job is not None and job.target_id == ready_vrc.id
