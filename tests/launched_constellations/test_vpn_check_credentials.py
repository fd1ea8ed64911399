"""Verification's VPN check certificates: on record when issued, pending until the router has
the list that refuses them; the sweeper leaves a constellation a live job works on alone."""

from __future__ import annotations

import uuid

from cryptography import x509
from flask import Flask

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import vpn
from cloudsim.launched_constellations.check_sweeper import sweep_checks
from cloudsim.models import AuditEvent, Constellation, ConstellationState, Job, JobState, Machine


def _in_crl(crl: str, serial: int) -> bool:
    listed = x509.load_pem_x509_crl(crl.encode())
    return listed.get_revoked_certificate_by_serial_number(serial) is not None


def _constellation() -> Constellation:
    made = Constellation(name="vrc-c", kind="vrc", provider="local", state=ConstellationState.READY)
    made.machines.append(Machine(name="router", role="router", private_ip="10.211.4.50"))
    db.session.add(made)
    db.session.commit()
    return made


def test_a_check_certificate_is_pending_from_issue_until_forgotten(app: Flask) -> None:
    constellation = _constellation()
    assert vpn.pending_check_certificates(constellation) == []  # and no PKI made for it
    issued = vpn.issue_check_certificate(constellation, "cloudsim-verify-1")
    db.session.commit()
    assert vpn.pending_check_certificates(constellation) == [(issued.serial, "cloudsim-verify-1")]
    assert vpn.revoke_check_certificates(constellation) == [issued.serial]
    material = vpn.server_material(constellation)
    assert _in_crl(material.crl, issued.serial)
    assert "cloudsim-verify-1" in material.revoked
    # still pending: the router may not have the list yet
    assert vpn.pending_check_certificates(constellation) == [(issued.serial, "cloudsim-verify-1")]
    crl = material.crl
    assert vpn.revoke_check_certificates(constellation) == [issued.serial]
    assert vpn.server_material(constellation).crl == crl  # revoking twice changes nothing
    vpn.forget_check_certificates(constellation, [issued.serial])
    db.session.commit()
    assert vpn.pending_check_certificates(constellation) == []
    assert _in_crl(vpn.server_material(constellation).crl, issued.serial)
    audit = db.session.scalars(db.select(AuditEvent).filter_by(action="vpn.check_revoked")).one()
    assert audit.target_id == str(constellation.id)


def test_the_sweeper_leaves_a_check_a_live_job_may_still_finish(app: Flask) -> None:
    constellation = _constellation()
    issued = vpn.issue_check_certificate(constellation, "cloudsim-verify-2")
    db.session.add(
        Job(
            id=str(uuid.uuid4()),
            kind="constellation.launch",
            target_type="constellation",
            target_id=constellation.id,
            state=JobState.QUEUED,
        )
    )
    db.session.commit()
    config: Config = app.config["CLOUDSIM"]
    assert sweep_checks(config) == []
    assert vpn.pending_check_certificates(constellation) == [(issued.serial, "cloudsim-verify-2")]
