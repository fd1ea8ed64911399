"""The whole worker tree killed during verification's VPN check: its key is revoked, not kept.

The check's certificate is on record before its key is written; the resumed launch revokes
it on the router (CRL) and removes the key from disk. The sweeper does the same for a check
whose job nothing resumes.
"""

from __future__ import annotations

import os
import re
import shlex
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import cast

import pytest
from celery.contrib.testing.worker import start_worker
from cryptography import x509
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import sweep_jobs
from cloudsim.launched_constellations import service, vpn
from cloudsim.launched_constellations.check_sweeper import sweep_checks
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import Constellation, ConstellationState, JobState
from constellations.plans.router import PKI_DIR
from provisioners.remote.ssh import SSHExecutor
from tests.conftest import running_app
from tests.launched_constellations.conftest import destroy_everything, finished, hosts_config
from tests.support.servers import wait_for
from tests.support.workers import kill_worker_tree, worker_process

pytestmark = pytest.mark.hosts
PREFIX = f"vk{os.getpid() % 100000}"


@pytest.fixture
def check_config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 224)


@pytest.fixture
def check_app(check_config: Config) -> Iterator[Flask]:
    with running_app(check_config) as app:
        try:
            yield app
        finally:
            destroy_everything(check_config)


def _serial(ovpn: Path) -> int:
    pem = re.search(r"<cert>\s*(.*?)\s*</cert>", ovpn.read_text(), re.S)
    assert pem is not None
    return x509.load_pem_x509_certificate(pem.group(1).encode()).serial_number


def _router_crl_serials(constellation: Constellation, config: Config) -> set[int]:
    keys = constellation_keypair(constellation)
    reach = targets(constellation, keys, config)
    router = next(m.name for m in constellation.machines if m.role == "router")
    executor = SSHExecutor(machine_host_keys(constellation), secrets=[keys.private])
    with executor:
        text = executor.run(
            reach[router],
            f"openssl crl -noout -text -in {shlex.quote(PKI_DIR + '/crl.pem')}",
            timeout=30,
        ).stdout
    return {int(found, 16) for found in re.findall(r"Serial Number: ([0-9A-Fa-f]+)", text)}


def _key_files(root: Path) -> list[Path]:
    return [p for p in root.rglob("*") if p.is_file()] if root.exists() else []


@pytest.mark.timeout(1500)  # a launch, killed and resumed
def test_a_check_killed_with_its_worker_tree_is_revoked_and_leaves_no_key(
    check_app: Flask, check_config: Config, pytestconfig: pytest.Config
) -> None:
    checks = check_config.instance_dir / "vpn-checks"
    tmp_before = set(Path("/tmp").glob("cloudsim-vpncheck-*"))
    process = worker_process(check_config, pytestconfig.rootpath)
    try:
        constellation, job = service.launch(SYSTEM, name="vpnkill", kind="vrc", provider="local")
        db.session.commit()  # sends the launch job
        # the check is under way: its client's key is on disk, its client connecting
        found = cast(
            Path,
            wait_for(
                lambda: next(iter(checks.rglob("check.ovpn")), None), 900, "the VPN check's client"
            ),
        )
        serial = _serial(found)
        assert (found.parent.stat().st_mode & 0o777) == 0o700
        assert str(found).startswith(str(check_config.instance_dir))
    finally:
        kill_worker_tree(process)  # the worker, its pool and the check's OpenVPN client
    assert set(Path("/tmp").glob("cloudsim-vpncheck-*")) == tmp_before  # nothing under /tmp
    db.session.expire_all()
    # recorded before it was used
    pending = dict(vpn.pending_check_certificates(constellation))
    assert serial in pending, pending

    with start_worker(
        check_app.extensions["celery"], pool="solo", perform_ping_check=False, loglevel="WARNING"
    ):
        wait_for(lambda: sweep_jobs() > 0, 60, "the dead worker's lease to expire")
        done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-4000:]}"
    assert "revoked on the router" in done.log
    db.session.expire_all()
    constellation = db.session.get(Constellation, constellation.id)  # type: ignore[assignment]
    assert constellation.state == ConstellationState.READY
    assert serial in _router_crl_serials(constellation, check_config)
    assert vpn.pending_check_certificates(constellation) == []
    assert _key_files(checks) == []

    # a check whose job died and that nothing resumes: the sweeper revokes it
    issued = vpn.issue_check_certificate(constellation, "cloudsim-verify-orphan")
    db.session.commit()
    orphan = checks / str(constellation.id) / "cloudsim-verify-orphan"
    orphan.mkdir(mode=0o700, parents=True)
    (orphan / "check.ovpn").write_text("key material")
    assert sweep_checks(check_config) == [issued.serial]
    assert issued.serial in _router_crl_serials(constellation, check_config)
    assert _key_files(checks) == [] and vpn.pending_check_certificates(constellation) == []
