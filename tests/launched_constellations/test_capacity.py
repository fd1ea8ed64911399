"""The local provider's capacity: known before a launch, a launch past it refused, the kernel
limits its hosts share raised once; verification retrying a check that passes late."""

from __future__ import annotations

import json
import os
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask import Flask

from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.launched_constellations.verify import Retry, _probe_public
from cloudsim.models import Role
from cloudsim.providers.service import open_provider
from provisioners.providers.local.capacity import Budget, KernelLimit, raise_limits, read_limit
from tests.conftest import make_user, running_app, token_for
from tests.support.servers import RedisServer

PREFIX = f"cq{os.getpid() % 100000}"


@pytest.fixture
def small_app(make_config: Callable[..., Config]) -> Iterator[Flask]:
    """An app whose local provider may run five hosts: room for one vrc (four) and a simple."""
    if os.geteuid() != 0:
        pytest.fail("the local provider's capacity needs root")
    with running_app(make_config(local_prefix=PREFIX, local_max_hosts=5)) as app:
        yield app


def test_a_launch_past_capacity_is_refused_with_the_figure_and_creates_nothing(
    small_app: Flask,
) -> None:
    client = small_app.test_client()
    headers = token_for(make_user(Role.ADMIN))
    room = client.get("/api/v1/constellations/capacity", headers=headers).get_json()
    assert room["known"] and room["hosts"] == 5
    assert room["kinds"]["vrc"] == 1 and room["kinds"]["simple"] == 5

    first = client.post(
        "/api/v1/constellations", json={"name": "one", "kind": "vrc"}, headers=headers
    )
    assert first.status_code == 202, first.get_json()
    room = client.get("/api/v1/constellations/capacity?provider=local", headers=headers).get_json()
    assert room["hosts"] == 1 and room["kinds"]["vrc"] == 0  # a launch not yet made counts

    refused = client.post(
        "/api/v1/constellations", json={"name": "two", "kind": "vrc"}, headers=headers
    )
    assert refused.status_code == 409
    message = refused.get_json()["message"]
    assert "room for 1" in message and "4 hosts" in message and "configured maximum" in message
    listed = client.get("/api/v1/constellations", headers=headers).get_json()
    assert [c["name"] for c in listed] == ["one"]
    assert open_provider("local", small_app.config["CLOUDSIM"]).driver.list_nodes() == []
    fits = client.post(
        "/api/v1/constellations", json={"name": "three", "kind": "simple"}, headers=headers
    )
    assert fits.status_code == 202


def test_the_command_line_refuses_with_one_line_and_says_the_room(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str
) -> None:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_LOCAL_PREFIX": PREFIX,
        "CLOUDSIM_LOCAL_MAX_HOSTS": "4",
    }

    def run(*args: str) -> tuple[int, str]:
        result = CliRunner().invoke(main, list(args), env=env)
        return result.exit_code, result.output

    assert run("db", "upgrade")[0] == 0
    code, output = run("constellation", "launch", "--name", "a", "--kind", "vrc")
    assert code == 0 and "local: room for 0 more host(s)" in output, output
    code, output = run("constellation", "launch", "--name", "b", "--kind", "simple")
    assert code != 0
    assert output.strip().splitlines() == [
        "Error: cannot launch a simple constellation: this machine can take 0 more host(s) "
        "(limited by configured maximum); the launch needs 1 hosts (room for 0)"
    ]
    code, output = run("constellation", "capacity", "--json")
    assert code == 0 and json.loads(output)["hosts"] == 0


def test_kernel_limits_are_raised_to_the_hosts_needs_once(tmp_path: Path) -> None:
    low = KernelLimit("fs.inotify.max_user_instances", 16, 512, 1 << 20)
    high = KernelLimit("kernel.keys.maxkeys", 16, 200, 1 << 20)
    for limit, value in ((low, 128), (high, 1 << 19)):
        limit.path(tmp_path).parent.mkdir(parents=True, exist_ok=True)
        limit.path(tmp_path).write_text(f"{value}\n")
    budget = Budget(max_hosts=10)
    changed = raise_limits(budget, (low, high), tmp_path)
    assert changed == ["fs.inotify.max_user_instances 128 -> 672"]  # 512 + 16 x 10 hosts
    assert read_limit(high, tmp_path) == 1 << 19  # already above: left alone
    assert raise_limits(budget, (low, high), tmp_path) == []
    # and on this machine's kernel: a second preparation changes nothing
    driver = open_provider_for(tmp_path)
    driver.ex_prepare()
    assert driver.ex_prepare() == []
    instances = KernelLimit("fs.inotify.max_user_instances", 0, 0, 0)
    assert (read_limit(instances) or 0) >= 512 + 16


def open_provider_for(tmp_path: Path):  # type: ignore[no-untyped-def]
    from provisioners.providers.local.driver import LocalNodeDriver

    return LocalNodeDriver(state_dir=str(tmp_path / "state"), prefix=PREFIX, max_hosts=1)


def test_verification_retries_a_port_that_opens_late_and_gives_up_in_bounded_time() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    listener = socket.socket()
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    logged: list[str] = []

    def attempt() -> tuple[bool, bool]:
        connected = _probe_public(lambda address, port: None, "127.0.0.1", port)
        if not connected:  # the port opens once it has been refused: the retry must reach it
            listener.bind(("127.0.0.1", port))
            listener.listen()
        return connected, connected

    try:
        assert Retry(30, logged.append).until("public -> sim:7700 connects", attempt)
    finally:
        listener.close()
    assert "failed (try 1), retrying in 1 s" in logged[0]
    assert logged[-1] == "public -> sim:7700 connects: passed on try 2"

    logged.clear()
    started = time.monotonic()
    assert not Retry(1.5, logged.append).until("never", lambda: (False, False))
    assert time.monotonic() - started >= 1.5  # it kept trying for the time it was given
    assert logged[-1] == "never: still failing after 3 tries; giving up"
