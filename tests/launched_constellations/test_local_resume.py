"""A worker killed in the middle of a launch: the launch resumes and leaks nothing."""

from __future__ import annotations

import pytest
from celery.contrib.testing.worker import start_worker
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import sweep_jobs
from cloudsim.launched_constellations import service
from cloudsim.models import ConstellationState, Job, JobState
from cloudsim.providers.service import open_provider
from tests.launched_constellations.conftest import finished, leftovers
from tests.support.servers import wait_for
from tests.support.workers import kill_worker, worker_process

pytestmark = pytest.mark.hosts


def test_launch_resumes_after_the_worker_is_killed_mid_machines(
    constellations_app: Flask, constellations_config: Config, pytestconfig: pytest.Config
) -> None:
    process = worker_process(constellations_config, pytestconfig.rootpath)
    try:
        constellation, job = service.launch(SYSTEM, name="resume", kind="vrc", provider="local")
        db.session.commit()  # the test is the boundary: its commit sends the launch job

        def creating() -> bool:
            db.session.expire_all()
            return db.session.get(Job, job.id).stage == "machines"  # type: ignore[union-attr]

        wait_for(creating, 120, "the machines stage")
        # killed once a first host exists: the others are still being made
        provider = open_provider("local", constellations_config)
        wait_for(lambda: provider.nodes(constellation.name), 60, "a first host")
    finally:
        kill_worker(process)
    db.session.expire_all()
    assert db.session.get(Job, job.id).state == JobState.RUNNING  # type: ignore[union-attr]
    with start_worker(
        constellations_app.extensions["celery"],
        pool="solo",
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=30,
    ):
        wait_for(lambda: sweep_jobs() > 0, 30, "the dead worker's lease to expire")
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
        assert done.attempts == 2 and "resuming after an interrupted attempt" in done.log
        db.session.refresh(constellation)
        assert constellation.state == ConstellationState.READY
        nodes = open_provider("local", constellations_config).nodes(constellation.name)
        assert sorted(n.extra["tags"]["cloudsim:machine"] for n in nodes) == [
            "fc1",
            "fc2",
            "router",
            "sim",
        ]
        finished(service.terminate(SYSTEM, constellation.id).id)
    assert leftovers(constellations_config) == {"netns": [], "mounts": [], "files": []}
