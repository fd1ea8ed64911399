"""A worker on a second machine: a local host, given CloudSim from the same source bundle as
the `cloudsim` kind, runs `cloudsim worker` against the master's PostgreSQL and Redis over the
LAN (password logins) and runs there a run's start and stop jobs, and a launch and terminate
on an existing server; the run's logs land in the object store the master reads them from."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from drcsim.rundir import SCORE
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition import runs
from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service as constellations
from cloudsim.models import ConstellationState, Job, JobState, Role, Run, RunState
from cloudsim.monitoring import heartbeats
from cloudsim.monitoring.health import redis_client
from cloudsim.people import service as people_service
from cloudsim.providers.service import configure_provider, open_provider
from tests.competition.support import open_task
from tests.conftest import make_user, running_app
from tests.launched_constellations.conftest import hosts_config
from tests.support.lightweight_runs import SCORE_LOG
from tests.support.servers import MotoEndpoint, wait_for
from tests.support.worker_hosts import (
    WORKER_LOG,
    MasterServers,
    boot_hosts,
    cloudsim_bundle,
    install_cloudsim,
    master_servers,
    reachable_from_lan,
    server_inventory,
    sim_constellation,
    sim_stand_in,
    start_worker,
    stop_worker,
    worker_env,
    write_run_logs,
)

pytestmark = pytest.mark.hosts
PREFIX = f"wh{os.getpid() % 100000}"
NETWORKS = 241  # 10.241.0.0/16 and 198.18.41.0/24: this file's own
GATEWAY = "198.18.41.1"  # the public network's gateway: the master, as the hosts see it


@pytest.fixture
def servers(tmp_path: Path, moto_endpoint: MotoEndpoint) -> Iterator[MasterServers]:
    with master_servers(tmp_path, moto_endpoint.port, GATEWAY) as found:
        yield found


@pytest.fixture
def master_config(make_config: Callable[..., Config], servers: MasterServers) -> Config:
    return hosts_config(make_config, PREFIX, NETWORKS, **servers.master)


@pytest.fixture
def master(master_config: Config) -> Iterator[Flask]:
    try:
        with running_app(master_config) as app:
            yield app
    finally:
        open_provider("local", master_config).driver.ex_sweep()  # type: ignore[attr-defined]


def _finished(job_id: str, seconds: float) -> Job:
    db.session.commit()  # the test is the boundary: its commit sends the job

    def done() -> Job | None:
        db.session.rollback()  # see the other machine's commits
        job = db.session.get(Job, job_id)
        assert job is not None
        return job if job.state in (JobState.SUCCEEDED, JobState.FAILED) else None

    job = wait_for(done, seconds, f"job {job_id} on the worker machine")
    assert isinstance(job, Job)
    return job


def _job(run: Run, kind: str) -> Job:
    db.session.rollback()
    return db.session.scalars(
        db.select(Job).where(Job.kind == kind, Job.target_type == "run", Job.target_id == run.id)
    ).one()


@pytest.mark.timeout(2700)  # CloudSim installed, a run, a launch with the simulator
def test_a_worker_on_another_machine_runs_a_run_and_stores_its_logs(
    master: Flask, master_config: Config, servers: MasterServers, wheelhouse_cache: Path
) -> None:
    hosts = {"worker": "minimal", "sim": "minimal", "server": None}  # the server: systemd
    worker, sim, server = boot_hosts(master_config, "lan", hosts)
    driver = open_provider("local", master_config).driver
    cidr = driver.ex_get_network("lan").cidr  # type: ignore[attr-defined]
    sim_stand_in(sim)
    bundle = cloudsim_bundle(wheelhouse_cache, master_config.machine_python)
    install_cloudsim(worker, bundle)
    with reachable_from_lan(f"{PREFIX}-s-public", GATEWAY, servers.ports):
        pid = start_worker(worker, worker_env(master_config, servers, bundle))
        try:
            machine = worker.run("hostname").strip()
            assert machine and machine != os.uname().nodename

            team = people_service.create_team(SYSTEM, "Team LAN")
            db.session.commit()
            user = make_user(Role.USER, team)
            sim_constellation(team.id, "lanrun", sim)
            run = runs.start_run(user, open_task(team.id).id)
            db.session.commit()
            started = _finished(_job(run, "run.start").id, 300)
            assert started.state == JobState.SUCCEEDED, (
                f"{started.log}\n{worker.run(f'tail -50 {WORKER_LOG}')}"
            )
            # the job ran on the other machine, and says so
            assert f"on worker host {machine}\n" in started.log

            write_run_logs(sim, [run.id])
            runs.stop_run(user, run.id)
            db.session.commit()
            stopped = _finished(_job(run, "run.stop").id, 300)
            assert stopped.state == JobState.SUCCEEDED, stopped.log
            assert f"on worker host {machine}\n" in stopped.log

            # the master's readiness check and metrics hear the worker machine by its name
            heard = f"{heartbeats.WORKER}cloudsim@{machine}"
            wait_for(lambda: heard in heartbeats.heard(redis_client(master_config)), 30, heard)

            # a launch on existing servers the worker machine reaches on its LAN
            configure_provider("servers", {"inventory": server_inventory(server, cidr)})
            db.session.commit()
            constellation, job = constellations.launch(
                SYSTEM, name="lansim", kind="simple", provider="servers"
            )
            launched = _finished(job.id, 1500)
            assert launched.state == JobState.SUCCEEDED, f"{launched.error}\n{launched.log}"
            assert f"on worker host {machine}\n" in launched.log
            db.session.refresh(constellation)
            assert constellation.state == ConstellationState.READY
            assert server.run("hostname").strip() == "lansim-sim"
            ended = _finished(constellations.terminate(SYSTEM, constellation.id).id, 300)
            assert ended.state == JobState.SUCCEEDED, f"{ended.error}\n{ended.log}"
            assert f"on worker host {machine}\n" in ended.log
            assert server.run("hostname").strip() == "server"  # released as it was found
        finally:
            stop_worker(worker, pid)

    db.session.expire_all()
    ended_run = db.session.get(Run, run.id)
    assert ended_run is not None
    assert ended_run.state == RunState.FINISHED, ended_run.error
    assert ended_run.score == 1
    artifact = artifact_for(ended_run, SCORE)
    assert artifact is not None
    # the master reads from the store what the other machine put there
    store = LogStore(master_config)
    lines = store.lines(LogStore.object_name(run.id, artifact.filename))
    assert "".join(f"{line}\n" for line in lines) == SCORE_LOG
    assert not master_config.artifact_dir.exists()  # nothing went to a folder of the master
    # the worker machine logged in with the password; no job log shows it
    assert servers.password not in started.log + stopped.log
