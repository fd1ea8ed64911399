"""Lightweight live runs for the beat's tests and benchmark: minimal local hosts as machines.

A minimal local host (its own namespace, filesystem and sshd) stands for a run's sim and,
when asked, its router: stand-ins answer what supervision asks (`systemctl is-active` says
the simulator runs; `csrouter counters|status --json` answer as csrouter does) and the run's
folder holds a score log. The run's constellation has a machine row per role, each with the
host's route, so the beat makes one connection per machine as it does in production.
"""

from __future__ import annotations

import functools
import os
import shlex
import signal
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import timedelta

from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.competition.artifacts import run_dir
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import (
    SSH_KEY_NAME,
    KeyPair,
    constellation_secret,
    generate_keypair,
)
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Machine,
    Run,
    RunState,
    SecretKind,
    Task,
    utcnow,
)
from constellations.plans.router import CSROUTER_COMMAND
from provisioners.providers.local import netns
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget

SCORE_LOG = (
    '{"event": "run_start", "score": 0, "sim_time": 0.0, "wall_time": 1795337764.0}\n'
    '{"checkpoint": 1, "event": "checkpoint", "name": "gate", "points": 1, "score": 1, '
    '"sim_time": 5.0, "wall_time": 1795337765.0}\n'
)
SYSTEMCTL = "#!/bin/sh\nexit 0\n"
CSROUTER = """#!/bin/sh
case "$1" in
counters) echo '{"uplink": {"accepted": {"payload_bytes": 1000}, "spent_at": null},\
 "downlink": {"accepted": {"payload_bytes": 2000}, "spent_at": null}}' ;;
status) echo '{"faults": []}' ;;
esac
"""


@dataclass(frozen=True)
class Host:
    """A minimal local host and the key that logs in to it."""

    node: Node
    keys: KeyPair
    route: dict[str, object]

    def run(self, command: str) -> str:
        """Run a command on the host over a connection of its own; return its output."""
        proxy = self.route["proxy_command"]
        assert isinstance(proxy, list)
        target = SSHTarget(
            name=self.node.name,
            host=self.node.private_ips[0],
            private_key=self.keys.private,
            proxy_command=proxy,
        )
        with SSHExecutor(HostKeys()) as executor:
            return executor.run(target, command).stdout

    def signal(self, signum: signal.Signals) -> None:
        """Signal every process of the host: sshd, its sessions, the proxies into it."""
        for pid in netns.namespace_pids(self.node.extra["netns"]):
            os.kill(pid, signum)


def boot_hosts(driver: LocalNodeDriver, network: str, names: list[str]) -> list[Host]:
    """Boot minimal hosts on one new network, with the stand-ins installed."""
    lan = driver.ex_create_network(network)

    def boot(name: str) -> Host:
        keys = generate_keypair(name)
        node = driver.create_node(
            name, auth=NodeAuthSSHKey(keys.public), ex_network=lan, ex_init="minimal"
        )
        host = Host(node, keys, driver.ex_ssh_route(node).to_json())
        host.run(
            f"printf '%s' {shlex.quote(SYSTEMCTL)} > /usr/local/bin/systemctl"
            f" && printf '%s' {shlex.quote(CSROUTER)} > {CSROUTER_COMMAND}"
            f" && chmod +x /usr/local/bin/systemctl {CSROUTER_COMMAND}"
        )
        return host

    with ThreadPoolExecutor(max_workers=8) as pool:
        return list(pool.map(boot, names))


def live_run(team_id: int, name: str, host: Host, roles: tuple[str, ...] = ("sim",)) -> Run:
    """Add a ready constellation whose machines (one per role) are the host, and a running run."""
    constellation = Constellation(
        name=name,
        kind="vrc",
        provider="local",
        team_id=team_id,
        state=ConstellationState.READY,
    )
    db.session.add(constellation)
    db.session.flush()
    constellation_secret(
        constellation,
        SSH_KEY_NAME,
        SecretKind.SSH_PRIVATE_KEY,
        functools.partial(str, host.keys.private),
    )
    for role in roles:
        db.session.add(
            Machine(
                constellation_id=constellation.id,
                name=role,
                role=role,
                private_ip=host.node.private_ips[0],
                ssh_route=host.route,
            )
        )
    now = utcnow()
    task = Task(
        team_id=team_id,
        name=f"Task of {name}",
        world="vrc_task_2",
        run_config=1,
        window_start=now - timedelta(minutes=1),
        window_stop=now + timedelta(hours=1),
        uplink_bits=1_000_000,
        downlink_bits=8_000_000,
    )
    db.session.add(task)
    db.session.flush()
    run = Run(
        task_id=task.id,
        team_id=team_id,
        constellation_id=constellation.id,
        active_constellation_id=constellation.id,
        state=RunState.RUNNING,
        running_at=now,
    )
    db.session.add(run)
    db.session.commit()
    folder = run_dir(run.id)
    host.run(f"mkdir -p {folder} && printf '%s' {shlex.quote(SCORE_LOG)} > {folder}/score.jsonl")
    return run
