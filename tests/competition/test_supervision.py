"""The beat against real local hosts: kept connections, a hung machine, terminated machines."""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from flask import Flask

from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.supervision import BeatReport, Supervisor
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.connect import forget_connections
from cloudsim.models import ConstellationState, RunState, Team
from provisioners.providers.local import netns
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import ConnectionCache, ConnectPolicy
from tests.support.lightweight_runs import Host, boot_hosts, live_run

pytestmark = pytest.mark.hosts
PREFIX = "csbeat"


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
        slow, quick = boot_hosts(driver, f"{PREFIX}-lan", ["slow", "quick"])
        yield {"slow": slow, "quick": quick}
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(scratch)
    assert netns.list_namespaces(f"{PREFIX}-") == []


def test_a_beat_keeps_connections_and_a_hung_machine_delays_no_other_run(
    app: Flask, team_a: Team, team_b: Team, hosts: dict[str, Host]
) -> None:
    slow = live_run(team_a.id, "a-beat", hosts["slow"])
    quick = live_run(team_b.id, "b-beat", hosts["quick"])
    config = replace(app.config["CLOUDSIM"], run_probe_seconds=3)
    cache = ConnectionCache()
    # a hung machine's question gives up sooner than in production, to keep the test short
    reach = ConnectPolicy(deadline=6.0, attempt_timeout=2.0, first_delay=0.1)
    supervisor = Supervisor(cache, command_seconds=5, reach=reach)
    try:
        first, second = beat(supervisor, config), beat(supervisor, config)
        assert (first.asked, first.answered, first.late) == (2, 2, [])
        assert (slow.score, quick.score) == (1, 1)
        # the second beat asked both machines again over the connections the first opened
        assert (second.asked, second.answered) == (2, 2)
        assert cache.stats().opened == 2 and cache.stats().reused >= 2

        hosts["slow"].signal(signal.SIGSTOP)
        try:
            hosts["quick"].run(f"touch {run_dir(quick.id)}/final.json")
            hung = beat(supervisor, config)
            # the quick run's end is acted on in the very beat the slow machine misses
            assert hung.late == [slow.id] and hung.stopped == 1
            assert (quick.state, quick.stop_reason) == (RunState.STOPPING, "ended")
            assert slow.state == RunState.RUNNING
        finally:
            hosts["slow"].signal(signal.SIGCONT)
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
