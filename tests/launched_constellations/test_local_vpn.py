"""The team VPN end to end: a bundle downloaded from the app connects a real OCU, with delay;
removing the user from the team cuts it off at once, and its client stops saying why."""

from __future__ import annotations

import io
import itertools
import re
import zipfile

import pytest
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
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import finished
from tests.support.servers import wait_for

pytestmark = pytest.mark.hosts


def _ocus(config: Config, names: list[str]) -> tuple[SSHExecutor, list[SSHTarget]]:
    """Make operator stations on the public side (they are no machines of the constellation)."""
    driver = open_provider("local", config).driver
    network = driver.ex_create_network("ocu-home")
    found = []
    for name in names:
        keys = generate_keypair(name)
        node = driver.create_node(
            name=name,
            auth=NodeAuthSSHKey(keys.public),
            ex_network=network,
            ex_public=True,
            size=driver.list_sizes()[0],
            image=driver.list_images()[0],
        )
        found.append(
            SSHTarget(
                name=name,
                host=node.private_ips[0],
                private_key=keys.private,
                proxy_command=node.extra["ssh_proxy_command"],
            )
        )
    return SSHExecutor(HostKeys()), found


def connect(executor: SSHExecutor, ocu: SSHTarget, config: str, address: str) -> float:
    """Start a stock OpenVPN client with config on ocu; return its first RTT to address, ms."""
    executor.put_file(ocu, config.encode(), "/etc/openvpn/client/team.conf", mode=0o600)
    executor.run(ocu, "systemctl start openvpn-client@team")

    def ping() -> str | None:
        result = executor.run(ocu, f"ping -n -c1 -W2 {address}", check=False, timeout=30)
        return result.stdout if result.ok else None

    reply = wait_for(ping, 60, f"{ocu.name} to reach {address} through the VPN")
    return float(re.search(r"time=([\d.]+) ms", str(reply)).group(1))  # type: ignore[union-attr]


def vpn_address(executor: SSHExecutor, ocu: SSHTarget) -> str:
    """Return the address the VPN gave the OCU."""
    return executor.run(ocu, "ip -4 -o addr show dev tun0 | awk '{print $4}'").stdout.strip()


def _download(app: Flask, user: User, constellation_id: int) -> str:
    response = app.test_client().get(
        f"/api/v1/constellations/{constellation_id}/vpn-bundle", headers=token_for(user)
    )
    assert response.status_code == 200, response.get_data(as_text=True)
    archive = zipfile.ZipFile(io.BytesIO(response.data))
    [config_name] = [n for n in archive.namelist() if n.endswith(".ovpn")]
    return archive.read(config_name).decode()


def test_bundle_connects_the_ocu_with_delay_and_revocation_cuts_only_that_member(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    team = create_team(SYSTEM, "Rovers")
    pilot, copilot = make_user(Role.USER, team), make_user(Role.USER, team)
    constellation, job = service.launch(
        SYSTEM, name="vpnteam", kind="vrc", provider="local", team_id=team.id
    )
    done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    db.session.refresh(constellation)
    fc1 = next(m for m in constellation.machines if m.name == "fc1").private_ip
    configs = [_download(constellations_app, user, constellation.id) for user in (pilot, copilot)]
    assert "OPENSSH PRIVATE KEY" not in configs[0]
    executor, (ocu, other) = _ocus(constellations_config, ["ocu", "ocu2"])
    with executor:
        assert not executor.run(ocu, f"ping -c1 -W1 {fc1}", check=False).ok  # not without VPN
        assert connect(executor, ocu, configs[0], fc1) >= 400  # 250 ms each way, by csrouter
        connect(executor, other, configs[1], fc1)
        address = vpn_address(executor, other)
        # the other member pings fc1 every 0.1 s through the whole revocation
        executor.run(
            other,
            f"nohup ping -n -D -i 0.1 -W 2 {fc1} > /root/ping.log 2>&1 & echo $! > /root/ping.pid",
        )

        update_user(SYSTEM, pilot.id, active=False)  # off the team: revoked, CRL pushed
        refresh = wait_for(lambda: _refresh_job(constellation.id), 30, "the VPN refresh job")
        assert finished(refresh).state == JobState.SUCCEEDED

        def cut_off() -> bool:
            return not executor.run(ocu, f"ping -c1 -W2 {fc1}", check=False, timeout=30).ok

        wait_for(cut_off, 30, "the revoked OCU to lose the LAN")
        executor.run(other, "sleep 2; kill -INT $(cat /root/ping.pid)")
        ping_log = executor.run(other, "cat /root/ping.log").stdout
        replies = [int(found) for found in re.findall(r"icmp_seq=(\d+)", ping_log)]
        gap = max(b - a for a, b in itertools.pairwise(replies))
        # the figure the README quotes: the other member's longest gap during a revocation
        print(f"other member's longest gap: {(gap - 1) * 0.1:.1f} s over {len(replies)} replies")
        assert vpn_address(executor, other) == address  # no reconnection, same address
        journal = executor.run(other, "journalctl -u openvpn-client@team --no-pager -o cat").stdout
        assert journal.count("Initialization Sequence Completed") == 1
        assert gap == 1, f"the other member lost {gap - 1} pings in a row"
        # the revoked member's stock client stops, and its log says why (it does not retry)
        wait_for(lambda: not _client_runs(executor, ocu), 30, "the revoked client to exit")
        log = _client_log(executor, ocu)
        assert "Halt command was pushed by server" in log, log[-3000:]
        assert "your VPN certificate was revoked" in log, log[-3000:]


def _client_runs(executor: SSHExecutor, ocu: SSHTarget) -> bool:
    """Tell whether the stock client's unit still runs on the OCU."""
    return executor.run(ocu, "systemctl is-active openvpn-client@team", check=False).ok


def _client_log(executor: SSHExecutor, ocu: SSHTarget) -> str:
    """Return the stock client's journal on the OCU."""
    return executor.run(ocu, "journalctl -u openvpn-client@team --no-pager -o cat").stdout


def _refresh_job(constellation_id: int) -> str | None:
    from sqlalchemy import select

    from cloudsim.models import Job

    db.session.expire_all()
    return db.session.scalar(
        select(Job.id).where(
            Job.kind == "constellation.refresh_access", Job.target_id == constellation_id
        )
    )
