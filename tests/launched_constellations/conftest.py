"""Fixtures for constellation tests on the local provider: a private prefix, a worker."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from flask import Flask
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job
from cloudsim.providers.service import open_provider
from tests.conftest import running_app
from tests.support.workers import job_finished

PREFIX = f"cf{os.getpid() % 100000}"


def hosts_config(
    make_config: Callable[..., Config], prefix: str, networks: int, **settings: object
) -> Config:
    """Return a config for local hosts on a prefix and networks of their own (10.N.0.0/16 and
    198.18.M.0/24 with M = N - 200), so that test files never share a host or a network."""
    if os.geteuid() != 0:
        pytest.fail("local host tests need root (the local provider makes namespaces)")
    return make_config(
        local_prefix=prefix,
        local_subnet_pool=f"10.{networks}.0.0/16",
        local_public_cidr=f"198.18.{networks - 200}.0/24",
        job_lease_seconds=5,
        # eight engineers' tests share two cores: a launch must not fail for the load alone
        # (production keeps CLOUDSIM_SIM_MIN_RTF at 1.0; tests/launched_constellations checks it)
        **{"sim_min_rtf": 0.05, **settings},
    )


@pytest.fixture
def constellations_config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 213)


@pytest.fixture
def constellations_app(constellations_config: Config) -> Iterator[Flask]:
    with running_app(constellations_config) as app:
        try:
            yield app
        finally:
            destroy_everything(constellations_config)


def destroy_everything(config: Config) -> None:
    """Remove every host and network a test made, even when it failed half-way."""
    driver = open_provider("local", config).driver
    driver.ex_sweep()  # type: ignore[attr-defined]


@pytest.fixture
def constellations_worker(constellations_app: Flask) -> Iterator[None]:
    with start_worker(
        constellations_app.extensions["celery"],
        pool="threads",
        concurrency=3,
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=30,
    ):
        yield


def finished(job_id: str, timeout: float = 600) -> Job:
    """Wait (long: machines are made) for a job to reach a final state; return its row."""
    return job_finished(job_id, timeout)


def leftovers(config: Config) -> dict[str, list[str]]:
    """Return every namespace, mount and state file the local provider left with our prefix."""
    netns = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    mounts = Path("/proc/mounts").read_text()
    state = config.instance_dir / "local-hosts"
    return {
        "netns": [
            line.split()[0] for line in netns.splitlines() if line.startswith(config.local_prefix)
        ],
        "mounts": [line for line in mounts.splitlines() if str(state) in line],
        "files": [str(p) for p in state.rglob("*") if p.is_file() and "lock" not in p.name]
        if state.exists()
        else [],
    }


def access_refreshes(constellation_id: int) -> list[Job]:
    """The jobs that pushed a constellation's access (team sudo, keys) to its machines."""
    db.session.expire_all()
    return list(
        db.session.scalars(
            select(Job).where(
                Job.kind == "constellation.refresh_access", Job.target_id == constellation_id
            )
        )
    )
