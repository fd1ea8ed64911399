"""Capacity counted from measurement: each role's host counts as bench/host_memory.py measured
it; under a small host budget the local provider takes `cloudsim` hosts until it is spent,
each accepted launch reaches ready and stays within the memory it was counted as, and the next
launch is refused with the reason."""

from __future__ import annotations

import os
from collections.abc import Callable

import pytest
from celery.contrib.testing.worker import start_worker

from bench.host_memory import upper_kib
from bench.local_hosts import host_pss_kib
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState, JobState, Role
from cloudsim.providers.service import open_provider
from provisioners.providers.local.host_memory import measured
from tests.conftest import make_user, running_app, token_for
from tests.launched_constellations.conftest import (
    destroy_everything,
    finished,
    hosts_config,
    leftovers,
)

pytestmark = pytest.mark.hosts
PREFIX = f"cm{os.getpid() % 100000}f"
FITTING = 2  # cloudsim hosts the budget holds


def test_each_kind_counts_its_roles_measured_memory(make_config: Callable[..., Config]) -> None:
    figures = measured()
    config = hosts_config(make_config, PREFIX, 237)
    with running_app(config) as app:
        client = app.test_client()
        headers = token_for(make_user(Role.ADMIN))
        room = client.get("/api/v1/constellations/capacity", headers=headers).get_json()
    counted = room["host_memory_mib"]
    assert counted["cloudsim"] == figures.of("cloudsim") > 2 * figures.of("fc")
    vrc = figures.of("router") + figures.of("sim") + 2 * figures.of("fc")
    # memory is the scarcest resource for team CloudSims here (threads allow many more)
    assert room["kinds"]["cloudsim"] <= room["memory_mib"] // counted["cloudsim"], room
    assert room["kinds"]["vrc"] <= room["memory_mib"] // vrc, room
    assert room["kinds"]["cloudsim"] < room["kinds"]["simple"], room


@pytest.mark.timeout(1800)  # two team CloudSims launched side by side on two shared cores
def test_cloudsim_hosts_fill_a_small_budget_to_the_refusal(
    make_config: Callable[..., Config],
) -> None:
    per_host = measured().of("cloudsim")
    # two cloudsim installs at once on a loaded machine are quiet longer than the default
    config = hosts_config(make_config, PREFIX, 237, local_max_hosts=FITTING, job_stall_seconds=1200)
    with running_app(config) as app:
        try:
            client = app.test_client()
            headers = token_for(make_user(Role.ADMIN))
            room = client.get("/api/v1/constellations/capacity", headers=headers).get_json()
            assert room["kinds"]["cloudsim"] == FITTING, room
            with start_worker(
                app.extensions["celery"], pool="threads", concurrency=2,
                perform_ping_check=False, loglevel="WARNING", shutdown_timeout=60,
            ):  # fmt: skip
                jobs = []
                for number in range(1, FITTING + 1):
                    body = {"name": f"fill-{number}", "kind": "cloudsim", "provider": "local"}
                    answer = client.post("/api/v1/constellations", json=body, headers=headers)
                    assert answer.status_code == 202, answer.get_json()
                    jobs.append(answer.get_json()["job"]["id"])
                body = {"name": "fill-over", "kind": "cloudsim", "provider": "local"}
                refused = client.post("/api/v1/constellations", json=body, headers=headers)
                assert refused.status_code == 409, refused.get_json()
                message = refused.get_json()["message"]
                assert message == (
                    "cannot launch a cloudsim constellation: this machine can take 0 more "
                    "host(s) (limited by configured maximum); the launch needs 1 hosts "
                    "(room for 0)"
                ), message
                for job_id in jobs:
                    done = finished(job_id, 1500)
                    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
                db.session.expire_all()
                states = {c.name: c.state for c in db.session.scalars(db.select(Constellation))}
                assert states == {
                    f"fill-{n}": ConstellationState.READY for n in range(1, FITTING + 1)
                }
                # each ready team CloudSim holds within the figure its admission counted
                provider = open_provider("local", config)
                driver = provider.driver
                for number in range(1, FITTING + 1):
                    (node,) = provider.nodes(f"fill-{number}")
                    used = (host_pss_kib(node) + upper_kib(driver.hosts_dir, node)) / 1024  # type: ignore[attr-defined]
                    assert used <= per_host, f"fill-{number} takes {used:.0f} MiB > {per_host}"
                room = client.get("/api/v1/constellations/capacity", headers=headers).get_json()
                assert room["kinds"]["cloudsim"] == 0 and room["hosts"] == 0, room
        finally:
            destroy_everything(config)
    assert leftovers(config) == {"netns": [], "mounts": [], "files": []}
