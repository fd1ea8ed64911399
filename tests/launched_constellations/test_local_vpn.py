"""The team VPN end to end: a bundle downloaded from the app connects a real OCU, with delay;
removing the user from the team cuts it off at once."""

from __future__ import annotations

import io
import re
import zipfile

from flask import Flask
from libcloud.compute.base import NodeAuthSSHKey

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.keys import generate_keypair
from cloudsim.models import JobState, Role, User
from cloudsim.people.service import create_team, update_user
from cloudsim.providers.service import open_provider
from provisioners.remote.ssh import HostKeys, SSHExecutor
from provisioners.remote.ssh import Machine as Target
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import finished
from tests.support.servers import wait_for


def _ocu(config: Config) -> tuple[SSHExecutor, Target]:
    """Make an operator station on the public side (it is no machine of the constellation)."""
    driver = open_provider("local", config).driver
    network = driver.ex_create_network("ocu-home")
    keys = generate_keypair("ocu")
    node = driver.create_node(
        name="ocu",
        auth=NodeAuthSSHKey(keys.public),
        ex_network=network,
        ex_public=True,
        size=driver.list_sizes()[0],
        image=driver.list_images()[0],
    )
    target = Target(
        name="ocu",
        host=node.private_ips[0],
        private_key=keys.private,
        proxy_command=node.extra["ssh_proxy_command"],
    )
    return SSHExecutor(HostKeys()), target


def _download(app: Flask, user: User, constellation_id: int) -> str:
    response = app.test_client().get(
        f"/api/v1/constellations/{constellation_id}/vpn-bundle", headers=token_for(user)
    )
    assert response.status_code == 200, response.get_data(as_text=True)
    archive = zipfile.ZipFile(io.BytesIO(response.data))
    [config_name] = [n for n in archive.namelist() if n.endswith(".ovpn")]
    return archive.read(config_name).decode()


def test_bundle_connects_the_ocu_with_delay_and_revocation_cuts_it_off(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    team = create_team(SYSTEM, "Rovers")
    pilot = make_user(Role.USER, team)
    constellation, job = service.launch(
        SYSTEM, name="vpnteam", kind="vrc", provider="local", team_id=team.id
    )
    done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    db.session.refresh(constellation)
    sim = next(m for m in constellation.machines if m.name == "sim").private_ip
    config = _download(constellations_app, pilot, constellation.id)
    assert "OPENSSH PRIVATE KEY" not in config
    executor, ocu = _ocu(constellations_config)
    with executor:
        assert not executor.run(ocu, f"ping -c1 -W1 {sim}", check=False).ok  # not without VPN
        executor.put_file(ocu, config.encode(), "/etc/openvpn/client/pilot.conf", mode=0o600)
        executor.run(ocu, "systemctl start openvpn-client@pilot")

        def ping() -> str | None:
            result = executor.run(ocu, f"ping -n -c1 -W2 {sim}", check=False, timeout=30)
            return result.stdout if result.ok else None

        reply = wait_for(ping, 60, "the OCU to reach sim through the VPN")
        rtt = float(re.search(r"time=([\d.]+) ms", str(reply)).group(1))  # type: ignore[union-attr]
        assert rtt >= 400  # 250 ms each way, added by the router's csrouter

        update_user(SYSTEM, pilot.id, active=False)  # off the team: revoked, CRL pushed
        refresh = wait_for(lambda: _refresh_job(constellation.id), 30, "the VPN refresh job")
        assert finished(refresh).state == JobState.SUCCEEDED

        def cut_off() -> bool:
            return not executor.run(ocu, f"ping -c1 -W2 {sim}", check=False, timeout=30).ok

        wait_for(cut_off, 30, "the revoked OCU to lose the LAN")
        log = executor.run(ocu, "journalctl -u openvpn-client@pilot --no-pager | tail -30").stdout
        assert "VERIFY" in log or "TLS" in log  # it keeps trying and is refused


def _refresh_job(constellation_id: int) -> str | None:
    from sqlalchemy import select

    from cloudsim.models import Job

    db.session.expire_all()
    return db.session.scalar(
        select(Job.id).where(
            Job.kind == "constellation.refresh_vpn", Job.target_id == constellation_id
        )
    )
