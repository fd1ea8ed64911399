"""A master launches a team's `vrc` constellation through the team's instance (the instance
provisions it on the `servers` provider, four bare local hosts standing in for the team's
servers), follows it, then is stopped while the team runs a task on its instance, and catches
up once restarted."""

from __future__ import annotations

import json
import shlex
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, cast

import pytest
from flask import Flask
from libcloud.compute.base import Node, NodeAuthSSHKey
from playwright.sync_api import expect, sync_playwright

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import instance_admin_token
from cloudsim.models import JobState, Role, TeamInstance
from cloudsim.people.service import create_team, update_user
from cloudsim.providers.service import open_provider
from cloudsim.team_instances import service
from cloudsim.team_instances.poll import check_instances
from tests.competition.support import open_task
from tests.conftest import log_in, make_user, token_for
from tests.launched_constellations.conftest import finished
from tests.provisioners.providers.servers.keys import KeyPair, make_key_pair
from tests.support.servers import wait_for
from tests.support.workers import kill_worker, worker_process
from tests.team_instances.test_local_instances import (
    instance_browser,
    log_in_instance,
    on_instance,
    ready,
)

pytestmark = [pytest.mark.hosts, pytest.mark.browser]


def _servers(config: Config, login: KeyPair) -> tuple[list[Node], str]:
    """Make four bare machines on one LAN, each with a public address at which the instance
    reaches it (the servers provider's inventory); return them and the LAN's CIDR."""
    driver = open_provider("local", config).driver
    lan = driver.ex_create_network("bare")

    def make(number: int) -> Node:
        return driver.create_node(
            name=f"bare-{number}",
            auth=NodeAuthSSHKey(login.public_line),
            ex_network=lan,
            ex_public=True,
            ex_init="systemd",
        )

    with ThreadPoolExecutor(max_workers=4) as pool:
        return list(pool.map(make, range(1, 5))), lan.cidr


def _launch(instance: TeamInstance, config: Config) -> dict[str, Any] | None:
    """Poll once (as the beat does); return the launch once the instance says it is done."""
    db.session.expire_all()
    check_instances(config, [instance.id])
    db.session.commit()
    launch = instance.launch or {}
    return launch if launch.get("state") in {"ready", "error", "failed"} else None


def test_a_constellation_through_an_instance_and_the_master_stopped(
    constellations_app: Flask,
    constellations_config: Config,
    pytestconfig: pytest.Config,
    tmp_path: Path,
) -> None:
    config = constellations_config
    team = create_team(SYSTEM, "Team A")
    member, admin = make_user(Role.USER, team), make_user(Role.ADMIN)
    login = make_key_pair("inventory")
    servers, cidr = _servers(config, login)
    # the master's worker: a process of its own, stopped (by its PID) and restarted below
    master = worker_process(config, pytestconfig.rootpath)
    try:
        ((instance, job),) = service.deploy(
            SYSTEM, name="team-a", provider="local", team_id=team.id
        )
        done = finished(job.id, 900)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
        wait_for(lambda: ready(config), 120, "the instance ready")

        # As the README says: the servers' inventory kept for the instance, then the launch.
        # First an inventory of three private servers (the router needs a public one): the
        # instance's launch fails and the master says why; with the fourth, public, server
        # added, the next launch resumes it.
        client = constellations_app.test_client()
        entries = [
            {
                "name": server.name,
                "address": server.public_ips[0],
                "private_ip": server.private_ips[0],
                "network": "bare",
                "cidr": cidr,
                "private_key": login.private,
            }
            for server in servers
        ]
        _launch_through(client, admin, instance, entries[1:])
        failed = cast(dict[str, Any], wait_for(lambda: _launch(instance, config), 300, "fail"))
        assert failed["state"] == "error" and "public" in failed["error"], failed
        # the router's public server; the others are reached through it once claimed
        router = {**entries[0], "public_ip": entries[0]["address"]}
        _launch_through(client, admin, instance, [router, *entries[1:]])
        launch = cast(dict[str, Any], wait_for(lambda: _launch(instance, config), 900, "launch"))
        assert launch["state"] == "ready", _remote_log(instance, config)
        assert (
            launch["progress"] == 100 and launch["constellation_id"] == failed["constellation_id"]
        )
        job = on_instance(instance, config, f"/jobs/{launch['job_id']}")
        for secret in (login.private, instance_admin_token(instance.constellation)):
            assert secret not in json.dumps(job)
        _catch_up(
            config,
            client,
            admin,
            member,
            instance,
            master,
            servers,
            login,
            tmp_path,
            pytestconfig.rootpath,
        )
    finally:
        if master.poll() is None:
            kill_worker(master)


def _launch_through(
    client: Any, admin: Any, instance: TeamInstance, inventory: list[dict[str, Any]]
) -> None:
    """Keep an inventory for the instance and launch through it, with the documented bodies."""
    answer = client.put(
        f"/api/v1/team-instances/{instance.id}/provider",
        json={"provider": "servers", "settings": {"inventory": inventory}},
        headers=token_for(admin),
    )
    assert answer.status_code == 200, answer.get_json()
    answer = client.post(
        "/api/v1/team-instances/launch",
        json={"kind": "vrc", "provider": "servers"},
        headers=token_for(admin),
    )
    assert answer.status_code == 200, answer.get_json()
    (row,) = answer.get_json()
    assert (row["instance"], row["team"], row["state"]) == ("team-a", "Team A", "launching")
    handed = finished(row["job_id"], 120)
    assert handed.state == JobState.SUCCEEDED, f"{handed.error}\n{handed.log}"
    assert inventory[0]["private_key"] not in handed.log
    assert instance_admin_token(instance.constellation) not in handed.log


def launch_id(instance: TeamInstance) -> int:
    """Return the id of the constellation launched through the instance, on the instance."""
    return int((instance.launch or {})["constellation_id"])


def _run_log(instance: TeamInstance, config: Config, run: dict[str, Any]) -> str:
    """Return why a run on the instance did not start: its error and its jobs' logs."""
    jobs = on_instance(instance, config, "/jobs?page_size=20")
    starts = [j for j in jobs if j["kind"].startswith("run.")]
    logs = [on_instance(instance, config, f"/jobs/{j['id']}") for j in starts[:3]]
    return f"{run.get('error')}\n" + "\n".join(
        f"{j['kind']} {j['state']} {j.get('error')}\n{j.get('log', '')[-3000:]}" for j in logs
    )


def _remote_log(instance: TeamInstance, config: Config) -> str:
    """Return the instance's launch job log, to say why its launch failed."""
    launch = instance.launch or {}
    if not launch.get("job_id"):
        return str(launch)
    job = on_instance(instance, config, f"/jobs/{launch['job_id']}")
    return f"{launch}\n{job.get('error')}\n{job.get('log', '')[-4000:]}"


def _catch_up(
    config: Config,
    client: Any,
    admin: Any,
    member: Any,
    instance: TeamInstance,
    master: subprocess.Popen[bytes],
    servers: list[Node],
    login: KeyPair,
    tmp: Path,
    root: Path,
) -> None:
    """The master stops; the team runs a task on its instance and is scored; the master is
    restarted, and its next poll catches up (health, sync, the constellation's state, a change
    made on the master during the outage)."""
    open_task(team_id=member.team_id, name="Walking", timeout_s=600)
    wait_for(
        lambda: "Walking" in {t["name"] for t in on_instance(instance, config, "/tasks")},
        60,
        "the task on the instance",
    )
    before = instance.last_sync_at
    kill_worker(master)  # the master's worker: no sync, no poll from here on
    update_user(SYSTEM, member.id, name="Renamed while the master was down")
    db.session.commit()  # its sync job waits in the queue: nobody runs it

    with sync_playwright() as playwright:
        browser = instance_browser(playwright, config, instance, tmp)
        page = browser.new_page()
        base = log_in_instance(page, instance, member)
        page.goto(f"{base}/tasks")
        page.get_by_role("button", name="Start run").click()
        expect(page.locator("#run-state")).not_to_have_text("starting", timeout=180_000)
        run_id = int(page.url.rstrip("/").split("/")[-1])
        started = on_instance(instance, config, f"/runs/{run_id}")
        assert started["state"] == "running", _run_log(instance, config, started)
        # the team's code drives the robot from fc1 (as root: the test owns the servers)
        launched = on_instance(instance, config, f"/constellations/{launch_id(instance)}")
        address = {m["name"]: m["private_ip"] for m in launched["machines"]}
        fc1 = next(n for n in servers if n.private_ips[0] == address["fc1"])
        proxy = shlex.join(fc1.extra["ssh_proxy_command"])
        controller = (
            "systemd-run --unit=example-controller --collect /opt/drcsim/bin/drcsim "
            f"example-controller --server {address['sim']} --world vrc_task_2 --timeout 120"
        )
        key = tmp / "login"
        key.write_text(login.private)
        key.chmod(0o600)
        subprocess.run(
            [
                "ssh",
                "-i",
                str(key),
                "-o",
                f"ProxyCommand={proxy}",
                "-o",
                "StrictHostKeyChecking=no",
                "-o",
                "UserKnownHostsFile=/dev/null",
                "-o",
                "LogLevel=ERROR",
                f"root@{fc1.private_ips[0]}",
                controller,
            ],
            check=True,
            timeout=60,
        )
        wait_for(
            lambda: on_instance(instance, config, f"/runs/{run_id}")["score"] >= 1,
            180,
            "a checkpoint",
        )
        page.goto(f"{base}/runs/{run_id}")
        page.get_by_role("button", name="Stop run").click()
        expect(page.get_by_text("Stopping the run.")).to_be_visible()
        browser.close()
    run = cast(
        dict[str, Any],
        wait_for(
            lambda: (
                (r := on_instance(instance, config, f"/runs/{run_id}"))["state"] == "finished" and r
            ),
            180,
            "the run scored and finished on the instance",
        ),
    )
    assert run["score"] >= 1 and run["end_reason"] == "stopped", run

    # The master is back: its next poll catches up.
    restarted = worker_process(config, root)
    try:
        db.session.expire_all()
        check_instances(config, [instance.id])
        db.session.commit()
        assert instance.state.value == "ready" and instance.health["worker"], instance.error
        assert instance.last_sync_at and before and instance.last_sync_at > before
        assert instance.sync_error is None
        assert (instance.launch or {})["state"] == "ready"
        users = {u["email"]: u["name"] for u in on_instance(instance, config, "/users")}
        assert users[member.email] == "Renamed while the master was down"
        log_in(client, admin)
        page_text = client.get(f"/team-instances/{instance.id}").get_data(as_text=True)
        assert "vrc on servers" in page_text and ">ready<" in page_text
    finally:
        kill_worker(restarted)
