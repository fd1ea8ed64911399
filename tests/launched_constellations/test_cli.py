"""`cloudsim constellation`: a waiting command runs its job itself when no worker is alive."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result

from tests.support.cli import migrated_cli
from tests.support.servers import RedisServer


@pytest.fixture
def run(tmp_path: Path, redis_server: RedisServer, encryption_key: str) -> Callable[..., Result]:
    return migrated_cli(
        tmp_path / "instance",
        redis_server.url(0),
        encryption_key,
        CLOUDSIM_LOCAL_PREFIX="t15cli",  # nothing of the local provider's is shared
    )


def test_terminate_wait_runs_the_job_itself_when_no_worker_is_alive(
    run: Callable[..., Result],
) -> None:
    launched = run("constellation", "launch", "--name", "demo", "--kind", "simple", "--json")
    assert launched.exit_code == 0, launched.output
    assert json.loads(launched.output)["state"] == "pending"  # no worker took the launch

    ended = run("constellation", "terminate", "demo", "--wait", "--json")
    assert ended.exit_code == 0, ended.output
    answer = json.loads(ended.stdout)
    assert answer["name"] == "demo" and answer["state"] == "terminated"
    assert "no worker is running" in ended.stderr
    assert all(m["state"] == "terminated" for m in answer["machines"])


def test_terminate_prints_json_without_waiting(run: Callable[..., Result]) -> None:
    run("constellation", "launch", "--name", "other", "--kind", "simple")
    ended = run("constellation", "terminate", "other", "--json")
    assert ended.exit_code == 0, ended.output
    assert json.loads(ended.stdout)["state"] == "terminating"
