"""Stuck jobs: a job that makes no progress is stopped with the reason and frees its slot."""

from __future__ import annotations

import json
import os
import shlex
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import JobState
from cloudsim.providers.service import open_provider
from tests.conftest import running_app
from tests.launched_constellations.conftest import hosts_config
from tests.support import job_kinds
from tests.support.lightweight_runs import Host, boot_hosts
from tests.support.workers import job_finished, kill_worker, worker_process

PREFIX = f"wd{os.getpid() % 100000}"
HANG = "#!/bin/sh\nsleep 3600\n"  # a `systemctl start` that never returns


def test_a_job_stuck_outside_any_step_is_failed_and_its_worker_slot_freed(
    make_config: Callable[..., Config], tmp_path: Path, pytestconfig: pytest.Config
) -> None:
    config = make_config(job_lease_seconds=30, job_stall_seconds=2)
    markers = tmp_path / "markers"
    markers.mkdir()
    with running_app(config) as app:
        assert app
        process = worker_process(config, pytestconfig.rootpath)  # one slot only
        try:
            stuck = enqueue("test.stuck", SYSTEM, job_kinds.Stuck())
            after = enqueue("test.slow", SYSTEM, job_kinds.Slow(str(markers), steps=2))
            done = job_finished(stuck.id, 180)
            assert done.state == JobState.FAILED
            assert "no progress for" in (done.error or "")
            assert "CLOUDSIM_JOB_STALL_SECONDS=2" in (done.error or "")
            assert "its worker process was ended" in (done.error or "")
            # the one slot works again: the job queued behind the stuck one runs
            assert job_finished(after.id, 180).state == JobState.SUCCEEDED
            db.session.expire_all()
            assert db.session.get(type(done), stuck.id).state == JobState.FAILED  # not re-run
        finally:
            kill_worker(process)


@pytest.fixture
def hang_host(make_config: Callable[..., Config]) -> Iterator[tuple[Config, Host, Path]]:
    config = hosts_config(make_config, PREFIX, 247, job_stall_seconds=3)
    driver = open_provider("local", config).driver
    try:
        host = boot_hosts(driver, f"{config.local_prefix}-wd", ["hang"])[0]  # type: ignore[arg-type]
        host.run(
            f"printf '%s' {shlex.quote(HANG)} > /usr/local/bin/systemctl"
            " && chmod +x /usr/local/bin/systemctl"
        )
        key = config.instance_dir / "hang.key"
        key.write_text(host.keys.private)
        yield config, host, key
    finally:
        driver.ex_sweep()  # type: ignore[attr-defined]


@pytest.mark.hosts
def test_a_command_hanging_on_a_host_fails_its_job_at_the_deadline_while_others_go_on(
    hang_host: tuple[Config, Host, Path], tmp_path: Path
) -> None:
    config, host, key = hang_host
    markers = tmp_path / "markers"
    markers.mkdir()

    def remote(command: str) -> job_kinds.Remote:
        return job_kinds.Remote(
            host=host.node.private_ips[0],
            proxy_command=json.dumps(host.route["proxy_command"]),
            key_file=str(key),
            command=command,
        )

    with (
        running_app(config) as app,
        start_worker(
            app.extensions["celery"],
            pool="threads",
            concurrency=2,
            perform_ping_check=False,
            loglevel="WARNING",
            shutdown_timeout=30,
        ),
    ):
        hung = enqueue("test.remote", SYSTEM, remote("systemctl start csrouter"))
        other = enqueue("test.slow", SYSTEM, job_kinds.Slow(str(markers), steps=8, seconds=1))
        done = job_finished(hung.id, 120)
        assert done.state == JobState.FAILED, done.log
        assert "stopped by the watchdog: no progress for" in (done.error or ""), done.error
        assert "systemctl start csrouter" in done.log
        # far within the command's own 600 s timeout
        assert done.finished_at and done.started_at
        assert (done.finished_at - done.started_at).total_seconds() < 120
        assert job_finished(other.id, 60).state == JobState.SUCCEEDED
        # the slot the hung job held takes the next job, and the host still answers
        after = enqueue("test.remote", SYSTEM, remote("hostname"))
        finished = job_finished(after.id, 60)
        assert finished.state == JobState.SUCCEEDED, finished.log
