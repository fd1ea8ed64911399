"""Two real team instances (local hosts, each its own CloudSim) each finish a run on the
constellation launched through them; both runs and their logs reach the master's portal
(its web server over pinned HTTPS, reached from the public network through a relay at the
network's gateway) and the leaderboard ranks the two teams by the VRC rules: Team A's run,
of a world whose first checkpoint an admin made one the robot holds from its first step,
scores it; Team B's scores nothing."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, cast

import pytest
from flask import Flask
from libcloud.compute.base import NodeAuthSSHKey
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import JobState, Role, Run, TeamInstance
from cloudsim.people.service import create_team
from cloudsim.portal.credentials import write_certificate
from cloudsim.providers.service import open_provider
from cloudsim.team_instances import service
from cloudsim.team_instances.poll import check_instances
from tests.competition.support import open_task
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import (  # noqa: F401 (fixtures used here)
    constellations_app,
    constellations_worker,
    finished,
    hosts_config,
)
from tests.portal.ingest_support import MasterServer
from tests.provisioners.providers.servers.keys import make_key_pair
from tests.support.relay import relay
from tests.support.servers import free_port, wait_for
from tests.team_instances.test_local_instances import on_instance, ready

# two team instances, two launches through them (each waited for up to 15 minutes), two runs
pytestmark = [pytest.mark.hosts, pytest.mark.timeout(3000)]
PREFIX = f"tp{os.getpid() % 100000}"
GATEWAY = "198.18.19.1"  # the public network's gateway: the master's portal, for the instances


@pytest.fixture
def constellations_config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 219, portal_url=f"https://{GATEWAY}:{free_port()}/")


def _launched(config: Config, instances: list[TeamInstance]) -> list[dict[str, Any]] | None:
    """Poll the instances once; return their launches once each is done."""
    db.session.expire_all()
    check_instances(config, [i.id for i in instances])
    db.session.commit()
    launches = [i.launch or {} for i in instances]
    done = all(launch.get("state") in {"ready", "error", "failed"} for launch in launches)
    return launches if done else None


def test_two_instances_runs_reach_the_portal_and_are_ranked(
    constellations_app: Flask,  # noqa: F811 (the fixture)
    constellations_worker: None,  # noqa: F811
    constellations_config: Config,
    pytestconfig: pytest.Config,
) -> None:
    config = constellations_config
    port = int(config.portal_url.rsplit(":", 1)[1].strip("/"))
    teams = [create_team(SYSTEM, "Team A"), create_team(SYSTEM, "Team B")]
    admin, officer = token_for(make_user(Role.ADMIN)), token_for(make_user(Role.OFFICER))
    client = constellations_app.test_client()
    # vrc_task_1's first checkpoint, as an admin edits it: outside the vehicle, from the start
    # (the instances get the world with their first sync; the second checkpoint needs driving)
    world = client.get("/api/v1/worlds/vrc_task_1", headers=admin).get_json()["document"]
    world["checkpoints"][0] = {"name": "by the vehicle", "when": {"not_flag": "robot_seated"}}
    edited = client.put("/api/v1/worlds/vrc_task_1", json={"document": world}, headers=admin)
    assert edited.status_code == 200 and edited.get_json()["changed"], edited.get_json()
    tasks = [
        # 8 s simulated: Team A's checkpoint holds from the first step, Team B's never comes
        open_task(team.id, name="Season run", world=world_name, timeout_s=8).id
        for team, world_name in zip(teams, ("vrc_task_1", "vrc_task_2"), strict=True)
    ]
    write_certificate(config, config.instance_dir / "tls")  # before the syncs: they hand it on
    server = MasterServer(config, port, pytestconfig.rootpath)
    server.start()
    try:
        deployed = [
            service.deploy(SYSTEM, name=f"team-{n}", provider="local", team_id=team.id)[0]
            for n, team in zip("ab", teams, strict=True)
        ]
        for _, job in deployed:
            done = finished(job.id, 900)
            assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
        instances = cast(list[TeamInstance], wait_for(lambda: ready(config), 120, "ready"))
        driver = open_provider("local", config).driver
        login = make_key_pair("inventory")
        for instance in instances:  # a bare server each, kept as the instance's inventory
            lan = driver.ex_create_network(f"bare-{instance.name}")
            node = driver.create_node(
                name=f"bare-{instance.name}",
                auth=NodeAuthSSHKey(login.public_line),
                ex_network=lan,
                ex_public=True,
                ex_init="systemd",
            )
            entry = {
                "name": node.name,
                "address": node.public_ips[0],
                "public_ip": node.public_ips[0],
                "private_ip": node.private_ips[0],
                "network": lan.name,
                "cidr": lan.cidr,
                "private_key": login.private,
            }
            answer = client.put(
                f"/api/v1/team-instances/{instance.id}/provider",
                json={"provider": "servers", "settings": {"inventory": [entry]}},
                headers=admin,
            )
            assert answer.status_code == 200, answer.get_json()
        answer = client.post(
            "/api/v1/team-instances/launch",
            json={"kind": "simple", "provider": "servers"},
            headers=admin,
        )
        assert answer.status_code == 200, answer.get_json()
        launches = cast(
            list[dict[str, Any]],
            wait_for(lambda: _launched(config, instances), 900, "both launches"),
        )
        assert [launch["state"] for launch in launches] == ["ready", "ready"], [
            (launch["state"], launch.get("error")) for launch in launches
        ]
        with relay(f"{PREFIX}-s-public", (GATEWAY, port), port):
            remote_runs = {}
            for instance in instances:  # the master's task, as the instance has it
                (task,) = [
                    t for t in on_instance(instance, config, "/tasks") if t["name"] == "Season run"
                ]
                run = on_instance(
                    instance, config, f"/tasks/{task['id']}/runs", method="POST", body={}
                )
                remote_runs[instance.id] = run["id"]

            def uploaded() -> list[Run] | None:
                db.session.expire_all()
                runs = list(db.session.scalars(select(Run).where(Run.instance_id.is_not(None))))
                complete = len(runs) == 2 and all(r.logs_complete_at for r in runs)
                return runs if complete else None

            try:
                runs = cast(list[Run], wait_for(uploaded, 240, "both runs on the portal"))
            except TimeoutError:
                seen = [on_instance(i, config, f"/runs/{remote_runs[i.id]}") for i in instances]
                refused = client.get("/api/v1/portal/refusals", headers=officer).get_json()
                settings = [on_instance(i, config, "/instance/health") for i in instances]
                raise AssertionError(f"{seen}\n{refused}\n{settings}") from None
        assert {(r.instance_id, r.remote_run_id) for r in runs} == set(remote_runs.items())
        assert {r.task_id for r in runs} == set(tasks)
        for run in runs:
            instance = next(i for i in instances if i.id == run.instance_id)
            theirs = on_instance(instance, config, f"/runs/{run.remote_run_id}")
            assert theirs["upload"]["state"] == "uploaded"
            assert theirs["upload"]["portal_run_id"] == run.id
            assert {(a["filename"], a["sha256"]) for a in theirs["artifacts"]} == {
                (a.filename, a.sha256) for a in run.artifacts
            }
            assert run.artifacts and (run.state.value, run.end_reason) == (
                theirs["state"],
                theirs["end_reason"],
            )
        by_team = {run.team_id: run for run in runs}
        run_a, run_b = by_team[teams[0].id], by_team[teams[1].id]
        assert (run_a.score, run_b.score) == (1, 0)
        assert [(e.checkpoint, e.description) for e in run_a.score_events if e.checkpoint] == [
            (1, "by the vehicle")
        ]
        board = client.get("/api/v1/leaderboard", headers=officer).get_json()
        assert [(s["rank"], s["team"], s["checkpoints"]) for s in board] == [
            (1, "Team A", 1),
            (2, "Team B", 0),
        ]
    finally:
        server.kill()
