"""`cloudsim constellation`: a waiting command runs its job itself when no worker is alive."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from cloudsim.cli import main
from tests.support.servers import RedisServer


@pytest.fixture
def run(tmp_path: Path, redis_server: RedisServer, encryption_key: str) -> Callable[..., Result]:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),  # a broker, but no worker behind it
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_LOCAL_PREFIX": "t15cli",  # nothing of the local provider's is shared
    }

    def invoke(*args: str) -> Result:
        return CliRunner().invoke(main, list(args), env=env)

    assert invoke("db", "upgrade").exit_code == 0
    return invoke


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
