"""The live reader against a real local host: figures cached once a second, read by the run's
page, the API and `cloudsim run watch` without touching the machine."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import tempfile
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask import Flask

from cloudsim.cli import main
from cloudsim.competition import live
from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.live import LiveReader
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Role, Run, Team, utcnow
from constellations.plans.router import CSROUTER_COMMAND
from provisioners.providers.local import netns
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import ConnectionCache
from tests.conftest import log_in, make_user, token_for
from tests.support.lightweight_runs import Host, boot_hosts, live_run

pytestmark = pytest.mark.hosts
PREFIX = "cslive"
CHECKPOINT = (
    '{"checkpoint": 2, "event": "checkpoint", "name": "gate_2", "points": 1, "score": 2, '
    '"sim_time": 9.5, "wall_time": 1795337769.0}\n'
)


@pytest.fixture(scope="module")
def host() -> Iterator[Host]:
    """Boot one minimal local host that stands for a run's sim, router and field computer."""
    if os.geteuid() != 0:
        pytest.skip("local hosts need root")
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=PREFIX,
        subnet_pool="10.232.0.0/16",
        public_cidr="198.18.32.0/24",
    )
    try:
        [machine] = boot_hosts(driver, f"{PREFIX}-lan", ["machine"])
        yield machine
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        shutil.rmtree(scratch)
    assert netns.list_namespaces(f"{PREFIX}-") == []


def _write_live(host: Host, run: Run, sim_time: float, rtf: float) -> None:
    figures = json.dumps({"sim_time": sim_time, "rtf": rtf, "score": 1, "falls": 0})
    host.run(f"printf '%s' {shlex.quote(figures)} > {run_dir(run.id)}/live.json")


def test_the_reader_caches_a_runs_figures_and_every_view_reads_the_cache(
    app: Flask, team_a: Team, team_b: Team, host: Host, encryption_key: str
) -> None:
    run = live_run(team_a.id, "a-live", host, roles=("sim", "router", "fc"))
    config = app.config["CLOUDSIM"]
    reader = LiveReader(ConnectionCache())
    client = app.test_client()
    member = make_user(Role.USER, team_a)
    log_in(client, member)
    try:
        before = client.get(f"/runs/{run.id}/status").json
        assert before["live"] is False and before["sim_seconds"] == 0 and before["heard"] == {}

        _write_live(host, run, 7.25, 0.97)
        assert reader.refresh(config) == 1
        await_heard(reader, config, run.id, {"sim", "router", "fc"})
        status = client.get(f"/runs/{run.id}/status").json
        assert status["live"] is True and status["sim_seconds"] == 7.25
        assert status["rtf"] == 0.97 and status["score"] == 1
        assert [e["kind"] for e in status["events"]] == ["checkpoint"]
        # the stand-in router counts 1000 and 2000 payload bytes
        assert status["bits_used"] == {"uplink": 8000, "downlink": 16000}
        assert status["bits_left"]["uplink"] == 1_000_000 - 8000
        assert set(status["heard"]) == {"sim", "router", "fc"}
        assert "svg" in status["charts"]["score"]

        # the simulator moves on and logs a checkpoint: the next refresh shows both
        _write_live(host, run, 9.75, 1.01)
        host.run(f"printf '%s' {shlex.quote(CHECKPOINT)} >> {run_dir(run.id)}/score.jsonl")
        reader.refresh(config)
        await_sim_time(reader, config, run.id, 9.75)
        api = client.get(f"/api/v1/runs/{run.id}/live", headers=token_for(member)).json
        assert api["sim_seconds"] == 9.75 and api["score"] == 2
        assert [e["description"] for e in api["events"]] == ["gate", "gate_2"]
        other = make_user(Role.USER, team_b)
        hidden = client.get(f"/api/v1/runs/{run.id}/live", headers=token_for(other))
        assert hidden.status_code == 404  # another team's run: as if there were none

        # the bandwidth plots grow from the samples the reader keeps (one per answer)
        samples = live.samples(live.connection(config), run.id)
        assert len(samples) >= 2 and samples[-1][1:] == [8000, 16000]
        page = client.get(f"/runs/{run.id}").get_data(as_text=True)
        assert "Uplink bits used" in page and "9.8" in page and 'data-role="fc"' in page

        # a simulator whose time stops moving is flagged, with its code
        stale = (utcnow() - timedelta(seconds=60)).isoformat()
        cached, _ = live.read(live.connection(config), run.id)
        cached["sim_advanced_at"] = stale
        live.connection(config).set(live.KEY.format(run.id), json.dumps(cached))
        run.running_at = utcnow() - timedelta(seconds=60)
        db.session.commit()
        flags = client.get(f"/runs/{run.id}/status").json["flags"]
        assert [f["code"] for f in flags] == ["RUN-SIM-SILENT"]

        env = {
            "CLOUDSIM_INSTANCE_DIR": str(config.instance_dir),
            "CLOUDSIM_REDIS_URL": config.effective_redis_url,
            "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        }
        watched = CliRunner().invoke(main, ["run", "watch", str(run.id), "--lines", "2"], env=env)
        assert watched.exit_code == 0, watched.output
        lines = watched.output.splitlines()
        assert len(lines) == 2 and "t=9.8/" in lines[0] and "score=2" in lines[0]
        assert "RUN-SIM-SILENT" in lines[0]
    finally:
        reader._pool.shutdown(wait=True)
        reader.connections.clear()


def test_a_router_daemon_that_fails_leaves_the_connections_open(
    app: Flask, team_a: Team, host: Host
) -> None:
    """csrouter restarting fails the counters command, not the connection: closing the router's
    connection would also close the simulator's, which rides through it in a vrc."""
    run = live_run(team_a.id, "a-router-down", host, roles=("sim", "router"))
    config = app.config["CLOUDSIM"]
    reader = LiveReader(ConnectionCache())
    down = "#!/bin/sh\necho 'csrouter: the csrouter daemon does not answer' >&2\nexit 3\n"
    host.run(f"cp {CSROUTER_COMMAND} /tmp/csrouter.up")
    host.run(f"printf '%s' {shlex.quote(down)} > {CSROUTER_COMMAND}")
    try:
        for sim_time in (7.5, 8.5):  # past the stand-in score log's 5.0
            _write_live(host, run, sim_time, 1.0)
            await_sim_time(reader, config, run.id, sim_time)
        reader.refresh(config)
        cached, _ = live.read(live.connection(config), run.id)
        assert "router" not in cached.get("heard", {})  # it failed every time
        assert reader.connections.stats().evicted == 0
    finally:
        host.run(f"cp /tmp/csrouter.up {CSROUTER_COMMAND}")
        reader._pool.shutdown(wait=True)
        reader.connections.clear()


def await_heard(reader: LiveReader, config: Config, run_id: int, roles: set[str]) -> None:
    """Refresh until every role has answered (a late answer is applied by the next refresh)."""
    for _ in range(60):
        cached, _ = live.read(live.connection(config), run_id)
        if roles <= set(cached.get("heard", {})):
            return
        reader.refresh(config)
    raise AssertionError(f"run {run_id}: {roles} never all answered")


def await_sim_time(reader: LiveReader, config: Config, run_id: int, sim_time: float) -> None:
    """Refresh until the cached simulated time is the one written."""
    for _ in range(60):
        cached, _ = live.read(live.connection(config), run_id)
        if (cached.get("sim") or {}).get("sim_time") == sim_time:
            return
        reader.refresh(config)
    raise AssertionError(f"run {run_id}: simulated time never reached {sim_time}")
