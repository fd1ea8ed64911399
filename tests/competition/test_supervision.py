"""The beat against real local hosts: kept connections, a hung machine, terminated machines."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import pytest
from flask import Flask
from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.competition import runs
from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.supervision import BeatReport, Supervisor
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.connect import forget_connections
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
    Team,
    User,
)
from provisioners.providers.local import netns
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import ConnectionCache, HostKeys, SSHExecutor, SSHTarget
from tests.competition.support import SCORE_LOG, open_task

pytestmark = pytest.mark.hosts
PREFIX = "csbeat"
# what the sim's `systemctl is-active` says while the simulator runs (hosts have no systemd)
ACTIVE = "#!/bin/sh\nexit 0\n"


@dataclass(frozen=True)
class Host:
    """A local host standing for one constellation's sim, and the key that logs in to it."""

    node: Node
    keys: KeyPair
    route: dict[str, object]


@pytest.fixture(scope="module")
def hosts() -> Iterator[dict[str, Host]]:
    """Boot two minimal local hosts ("slow" and "quick"); destroy them after."""
    if os.geteuid() != 0:
        pytest.skip("local hosts need root")
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=PREFIX,
        subnet_pool="10.231.0.0/16",
        public_cidr="198.18.31.0/24",
    )
    try:
        lan = driver.ex_create_network(f"{PREFIX}-lan")
        made = {}
        for name in ("slow", "quick"):
            keys = generate_keypair(name)
            node = driver.create_node(
                name, auth=NodeAuthSSHKey(keys.public), ex_network=lan, ex_init="minimal"
            )
            made[name] = Host(node, keys, driver.ex_ssh_route(node).to_json())
        yield made
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(scratch)
    assert netns.list_namespaces(f"{PREFIX}-") == []


def live_run(user: User, team: Team, name: str, host: Host) -> Run:
    """Give the team a ready constellation whose sim is the host, and a running run on it."""
    constellation = Constellation(
        name=name, kind="vrc", provider="local", team_id=team.id, state=ConstellationState.READY
    )
    db.session.add(constellation)
    db.session.flush()
    constellation_secret(
        constellation, SSH_KEY_NAME, SecretKind.SSH_PRIVATE_KEY, lambda: host.keys.private
    )
    db.session.add(
        Machine(
            constellation_id=constellation.id,
            name="sim",
            role="sim",
            private_ip=host.node.private_ips[0],
            ssh_route=host.route,
        )
    )
    db.session.commit()
    run = runs.start_run(user, open_task(team.id).id)
    run.state = RunState.RUNNING
    db.session.commit()
    return run


def on_sim(host: Host, command: str) -> None:
    """Run a command on the host with a connection of the test's own."""
    target = SSHTarget(name="setup", host="", private_key=host.keys.private)
    route = host.route["proxy_command"]
    assert isinstance(route, list)
    target = replace(target, host=str(host.node.private_ips[0]), proxy_command=route)
    with SSHExecutor(HostKeys()) as executor:
        executor.run(target, command)


def signal_host(host: Host, signum: signal.Signals) -> None:
    """Send a signal to every process of the host (sshd, its sessions, our proxies into it)."""
    for pid in netns.namespace_pids(host.node.extra["netns"]):
        os.kill(pid, signum)


def test_a_beat_keeps_connections_and_a_hung_machine_delays_no_other_run(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team, hosts: dict[str, Host]
) -> None:
    slow = live_run(people["user_a"], team_a, "a-beat", hosts["slow"])  # type: ignore[arg-type]
    quick = live_run(people["user_b"], team_b, "b-beat", hosts["quick"])  # type: ignore[arg-type]
    for run, host in ((slow, hosts["slow"]), (quick, hosts["quick"])):
        folder = run_dir(run.id)
        on_sim(
            host,
            f"printf '{ACTIVE}' > /usr/local/bin/systemctl && chmod +x /usr/local/bin/systemctl"
            f" && mkdir -p {folder} && printf '%s' '{SCORE_LOG}' > {folder}/score.jsonl",
        )
    config = replace(app.config["CLOUDSIM"], run_probe_seconds=2)
    cache = ConnectionCache()
    supervisor = Supervisor(cache)
    try:
        first, second = beat(supervisor, config), beat(supervisor, config)
        assert (first.asked, first.answered, first.late) == (2, 2, [])
        assert (slow.score, quick.score) == (1, 1)
        # the second beat asked both machines again over the connections the first opened
        assert (second.asked, second.answered) == (2, 2)
        assert cache.stats().opened == 2 and cache.stats().reused >= 2

        signal_host(hosts["slow"], signal.SIGSTOP)
        try:
            on_sim(hosts["quick"], f"touch {run_dir(quick.id)}/final.json")
            hung = beat(supervisor, config)
            # the quick run's end is acted on in the very beat the slow machine misses
            assert hung.late == [slow.id] and hung.stopped == 1
            assert (quick.state, quick.stop_reason) == (RunState.STOPPING, "ended")
            assert slow.state == RunState.RUNNING
        finally:
            signal_host(hosts["slow"], signal.SIGCONT)
        after = await_answer(supervisor, config, slow.id)
        assert slow.state == RunState.RUNNING and slow.score == 1 and after.late == []
        assert cache.stats().opened == 3  # the silent connection was replaced, once

        quick.constellation.state = ConstellationState.TERMINATED  # type: ignore[union-attr]
        db.session.commit()
        beat(supervisor, config)
        assert cache.names() == ["a-beat/sim"]
        # what the terminate job does in its own process
        assert forget_connections(slow.constellation, cache) == 1  # type: ignore[arg-type]
        assert cache.names() == []
    finally:
        supervisor.close()
        cache.clear()


def beat(supervisor: Supervisor, config: Config) -> BeatReport:
    """Run one beat and commit, as the beat's Celery task does."""
    report = supervisor.beat(config)
    db.session.commit()
    return report


def await_answer(supervisor: Supervisor, config: Config, run_id: int) -> BeatReport:
    """Beat until the run's machine has answered again (its late question comes back first)."""
    deadline = time.monotonic() + 60
    while True:
        report = beat(supervisor, config)
        if run_id not in report.late and run_id not in report.failed and report.answered:
            return report
        assert time.monotonic() < deadline, f"run {run_id} never answered again: {report}"
        time.sleep(0.2)  # the question still out is answered by a thread: await it
