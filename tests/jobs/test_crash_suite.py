"""The crash suite: workers killed at every stage of a launch, a run's start and stop and a
terminate, and a run stopped while it starts; the invariants checked after each.

One vrc constellation on local hosts carries the whole life. Each job is killed once at each of
its stages in turn: a worker that SIGKILLs itself (worker and pool) as the job enters stage S
takes it; once its lease runs out the sweep sends it again, to a worker that dies at the next
stage, and so on, until a plain worker finishes it. So one launch is killed at every stage of a
launch, one run start at every stage of a start, and so on. After each job: it ended
(succeeded, one attempt per kill and one more), the API answered no 5xx while it recovered;
after the run, its metering is complete (tests/competition/test_crash_metering.py's check);
after the terminate, no host, mount, host process or key of the constellation is left.
A second test stops a run through the API while its start is at the router step.

The whole `cloudsim up` tree killed at each stage is tests/jobs/test_crash_up.py.
"""

from __future__ import annotations

import os
import subprocess
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.jobs import machines, unit_name
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.runner import STAGE_HOOKS
from cloudsim.jobs.service import sweep_jobs
from cloudsim.launched_constellations import router_control
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Job,
    JobState,
    Role,
    Run,
    RunState,
    Secret,
    Team,
)
from cloudsim.people import service as people_service
from cloudsim.providers.service import open_provider
from provisioners.providers.local import processes
from tests.competition.support import open_task
from tests.competition.test_crash_metering import DOWNLINK_BITS, UPLINK_BITS, _check_metering
from tests.conftest import make_user, running_app, token_for
from tests.launched_constellations.conftest import (
    destroy_everything,
    finished,
    hosts_config,
    leftovers,
)
from tests.support.servers import wait_for
from tests.support.workers import crash_worker, kill_worker

pytestmark = pytest.mark.hosts
PREFIX = f"cx{os.getpid() % 100000}"
# the stages each job is killed at, in the order it enters them
LAUNCH = ["keys", "network", "machines", "firewall", "install", "verify", "ready"]
RUN_START = ["router", "simulator", "announce", "running"]
RUN_STOP = ["simulator", "router", "logs", "score"]
TERMINATE = ["stopping its jobs", "machines", "network", "keys", "terminated"]


@pytest.fixture
def crash_config(make_config: Callable[..., Config]) -> Config:
    # the machines' image is built once per test folder, quiet for minutes on a loaded
    # machine: the watchdog (tests/jobs/test_watchdog.py) must not stop that first build
    return hosts_config(make_config, PREFIX, 236, job_stall_seconds=1800)


@pytest.fixture
def crash_app(crash_config: Config) -> Iterator[Flask]:
    with running_app(crash_config) as app:
        try:
            yield app
        finally:
            destroy_everything(crash_config)


class Recovery:
    """Kill a job at each of its stages in turn, asking the API meanwhile: no 5xx."""

    def __init__(self, app: Flask, config: Config, root: Path, headers: dict[str, str]) -> None:
        self.app, self.config, self.root, self.headers = app, config, root, headers
        self.client: FlaskClient = app.test_client()
        self.answers: list[tuple[str, int]] = []

    def ask(self, *urls: str) -> None:
        """GET each URL through the API, as a user watching would; keep the answers."""
        for url in urls:
            self.answers.append((url, self.client.get(url, headers=self.headers).status_code))

    def killed_at_each(
        self, kind: str, stages: list[str], start: Callable[[], str], watch: list[str]
    ) -> Job:
        """Start a job (start() returns its id) on a worker dying at stages[0], resume it on one
        dying at each next stage, then finish it on a plain worker; return its row."""
        job_id = ""
        for number, stage in enumerate(stages):
            process = crash_worker(self.config, self.root, at=f"{kind}:{stage}")
            try:
                if number == 0:
                    job_id = start()
                    db.session.commit()  # the test is the boundary: its commit sends the job
                else:
                    self._resend(job_id)
                self._died(process, job_id, f"{kind}:{stage}", watch)
            finally:
                if process.poll() is None:
                    kill_worker(process)
            db.session.expire_all()
            job = db.session.get(Job, job_id)
            assert job is not None and job.state == JobState.RUNNING, (stage, job and job.state)
        with start_worker(
            self.app.extensions["celery"], pool="threads", concurrency=2,
            perform_ping_check=False, loglevel="WARNING", shutdown_timeout=30,
        ):  # fmt: skip
            self._resend(job_id)
            job = self._final(job_id, watch)
        assert job.state == JobState.SUCCEEDED, f"{kind}: {job.error}\n{job.log[-4000:]}"
        assert job.attempts == len(stages) + 1, (kind, job.attempts)
        failed = [(url, status) for url, status in self.answers if status >= 500]
        assert not failed, f"{kind}: 5xx while it recovered: {failed[:5]}"
        return job

    def _resend(self, job_id: str) -> None:
        """Wait for the dead worker's lease to run out and the sweep to send the job again."""

        def sent() -> bool:
            self.ask(f"/api/v1/jobs/{job_id}")
            return sweep_jobs() > 0

        wait_for(sent, 60, f"job {job_id}'s lease to expire")

    def _died(
        self, process: subprocess.Popen[bytes], job_id: str, where: str, watch: list[str]
    ) -> None:
        def dead() -> bool:
            self.ask(*watch, f"/api/v1/jobs/{job_id}")
            db.session.expire_all()
            job = db.session.get(Job, job_id)
            if job is not None and job.state.final:
                pytest.fail(f"{where}: the job ended ({job.state}) before the stage\n{job.log}")
            return process.poll() is not None

        wait_for(dead, 900, f"the worker to die at {where}")

    def _final(self, job_id: str, watch: list[str]) -> Job:
        def final() -> Job | None:
            self.ask(*watch, f"/api/v1/jobs/{job_id}")
            db.session.expire_all()
            job = db.session.get(Job, job_id)
            return job if job is not None and job.state.final else None

        return wait_for(final, 900, f"job {job_id} to finish")  # type: ignore[return-value]


def _run_job(run_id: int, kind: str) -> str:
    db.session.expire_all()
    return db.session.scalars(
        select(Job.id).where(Job.kind == kind, Job.target_type == "run", Job.target_id == run_id)
    ).one()


@pytest.mark.timeout(3600)  # one vrc's whole life, each job killed once per stage
def test_workers_killed_at_every_stage_lose_nothing(
    crash_app: Flask, crash_config: Config, pytestconfig: pytest.Config
) -> None:
    team = people_service.create_team(SYSTEM, "Team Crash")
    db.session.commit()
    member, admin = make_user(Role.USER, team), make_user(Role.ADMIN)
    admin_headers, member_headers = token_for(admin), token_for(member)
    recovery = Recovery(crash_app, crash_config, pytestconfig.rootpath, admin_headers)
    client = crash_app.test_client()

    def launch() -> str:
        body = {"name": "crash", "kind": "vrc", "provider": "local", "team_id": team.id}
        answer = client.post("/api/v1/constellations", json=body, headers=admin_headers)
        assert answer.status_code == 202, answer.get_data(as_text=True)
        return answer.get_json()["job"]["id"]  # type: ignore[no-any-return]

    watch = ["/api/v1/constellations"]
    recovery.killed_at_each("constellation.launch", LAUNCH, launch, watch)
    constellation = db.session.scalars(
        select(Constellation).where(Constellation.name == "crash")
    ).one()
    assert constellation.state == ConstellationState.READY, constellation.error
    watch.append(f"/api/v1/constellations/{constellation.id}")

    # a run started, its start killed at every stage, then stopped, its stop killed likewise
    task = open_task(
        team.id, timeout_s=600, uplink_bits=UPLINK_BITS, downlink_bits=DOWNLINK_BITS,
        latency_ms=100,
    )  # fmt: skip
    run_id = 0

    def start() -> str:
        nonlocal run_id
        answer = client.post(f"/api/v1/tasks/{task.id}/runs", json={}, headers=member_headers)
        assert answer.status_code == 202, answer.get_data(as_text=True)
        run_id = answer.get_json()["id"]
        return _run_job(run_id, "run.start")

    recovery.killed_at_each("run.start", RUN_START, start, watch)
    run = db.session.get(Run, run_id)
    assert run is not None and run.state == RunState.RUNNING, run and run.error

    def stop() -> str:
        answer = client.post(f"/api/v1/runs/{run_id}/stop", headers=member_headers)
        assert answer.status_code < 300, answer.get_data(as_text=True)
        db.session.commit()
        return _run_job(run_id, "run.stop")

    recovery.killed_at_each("run.stop", RUN_STOP, stop, [*watch, f"/api/v1/runs/{run_id}"])
    db.session.expire_all()
    run = db.session.get(Run, run_id)
    assert run is not None and run.state == RunState.FINISHED, run and run.error
    _check_metering(crash_config, run, "killed at every stage")

    # terminated, the terminate killed at every stage: nothing of the constellation is left
    provider = open_provider("local", crash_config)
    launchers = [
        processes.identify(n.extra["launcher_pid"])
        for n in provider.nodes(constellation.name)
        if n.extra.get("launcher_pid")
    ]
    assert launchers and all(launchers)

    def terminate() -> str:
        answer = client.delete(f"/api/v1/constellations/{constellation.id}", headers=admin_headers)
        assert answer.status_code == 202, answer.get_data(as_text=True)
        return answer.get_json()["id"]  # type: ignore[no-any-return]

    recovery.killed_at_each("constellation.terminate", TERMINATE, terminate, watch)
    db.session.expire_all()
    row = db.session.get(Constellation, constellation.id)
    assert row is not None and row.state == ConstellationState.TERMINATED, row and row.error
    assert provider.nodes(constellation.name) == []
    assert leftovers(crash_config) == {"netns": [], "mounts": [], "files": []}
    assert not [p for p in launchers if p is not None and processes.is_alive(p)]
    keys = select(func.count(Secret.id)).where(
        Secret.owner_type == "constellation", Secret.owner_id == constellation.id
    )
    assert db.session.scalar(keys) == 0, "a key of the terminated constellation is left"
    assert db.session.scalar(select(func.count(Job.id)).where(~Job.state.in_(FINAL))) == 0


FINAL = [JobState.SUCCEEDED, JobState.FAILED]


@pytest.mark.timeout(1800)
def test_a_run_stopped_while_it_starts_stops_at_the_next_step(
    crash_app: Flask, crash_config: Config
) -> None:
    """Stop a run (through the API) once its start armed the router: the simulator never
    starts, the stop job disarms the router, the run ends `finished`, ended by `stopped`."""
    team = people_service.create_team(SYSTEM, "Team Stop")
    db.session.commit()
    member, admin = make_user(Role.USER, team), make_user(Role.ADMIN)
    headers = token_for(member)
    app, client, config = crash_app, crash_app.test_client(), crash_config
    with start_worker(
        app.extensions["celery"], pool="threads", concurrency=2,
        perform_ping_check=False, loglevel="WARNING", shutdown_timeout=30,
    ):  # fmt: skip
        body = {"name": "stopping", "kind": "vrc", "provider": "local", "team_id": team.id}
        launched = client.post("/api/v1/constellations", json=body, headers=token_for(admin))
        assert launched.status_code == 202, launched.get_data(as_text=True)
        done = finished(launched.get_json()["job"]["id"])
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    _stopped_while_starting(app, client, team, headers, config)


def _stopped_while_starting(
    app: Flask, client: FlaskClient, team: Team, headers: dict[str, str], config: Config
) -> None:
    """Start a run and stop it (through the API) once its start armed the router."""
    task = open_task(team.id, timeout_s=600)
    reached, proceed = threading.Event(), threading.Event()

    def hold_there(kind: str, stage: str) -> None:
        # the start waits at its router step until the test has asked for the stop
        if (kind, stage) == ("run.start", "router") and not reached.is_set():
            reached.set()
            proceed.wait(120)

    STAGE_HOOKS.append(hold_there)
    try:
        with start_worker(
            app.extensions["celery"], pool="threads", concurrency=2,
            perform_ping_check=False, loglevel="WARNING", shutdown_timeout=30,
        ):  # fmt: skip
            answer = client.post(f"/api/v1/tasks/{task.id}/runs", json={}, headers=headers)
            assert answer.status_code == 202, answer.get_data(as_text=True)
            db.session.commit()
            run_id = answer.get_json()["id"]
            wait_for(reached.is_set, 300, "the start's router step")
            stopped = client.post(f"/api/v1/runs/{run_id}/stop", headers=headers)
            assert stopped.status_code == 202, stopped.get_data(as_text=True)
            assert stopped.get_json()["state"] == "starting"  # asked while it starts
            proceed.set()

            def ended() -> bool:
                db.session.expire_all()
                run = db.session.get(Run, run_id)
                return run is not None and run.state in (
                    RunState.FINISHED, RunState.ERROR, RunState.NEEDS_REVIEW,
                )  # fmt: skip

            wait_for(ended, 600, f"run {run_id} to end")
    finally:
        proceed.set()
        STAGE_HOOKS.remove(hold_there)
    start_job = db.session.get(Job, _run_job(run_id, "run.start"))
    stop_job = db.session.get(Job, _run_job(run_id, "run.stop"))
    assert start_job is not None and stop_job is not None
    assert start_job.state == JobState.SUCCEEDED, start_job.error
    assert "stop asked while starting" in start_job.log
    assert "== simulator" not in start_job.log  # stopped at its next step: no simulator
    assert stop_job.state == JobState.SUCCEEDED, f"{stop_job.error}\n{stop_job.log[-3000:]}"
    run = db.session.get(Run, run_id)
    assert run is not None
    assert run.state == RunState.FINISHED, (run.state, run.error)
    assert run.end_reason == "stopped" and run.running_at is None and run.error is None
    with machines(run, config) as reach:
        assert reach.router is not None
        unit = unit_name(run.id)
        active = reach.executor.run(
            reach.sim, f"systemctl is-active {unit} || true", timeout=30
        ).stdout.strip()
        assert active != "active", active
        found = router_control.status(reach.executor, reach.router)
        assert not found.get("armed"), found
