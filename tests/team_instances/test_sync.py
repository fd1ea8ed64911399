"""A master's desired state, applied on an instance through its documented API: idempotent,
drift put back, the same password logs in, only admins may push it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from drcsim.worlds import shipped_document
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.ssh_keys import add_key
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Role,
    Task,
    Team,
    TeamInstance,
    User,
)
from cloudsim.people.service import create_team, update_user
from cloudsim.team_instances import service
from cloudsim.team_instances.sync import desired_state
from cloudsim.worlds.service import update_world
from tests.competition.support import open_task
from tests.conftest import csrf_token, make_user, running_app, token_for

KEY = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIOMqqnkVzrm0SdG6UOoqKLsabgH5C9okWi0dh2l9GKJl"
DESIRED = "/api/v1/instance/desired-state"


def _master_state(config: Config) -> tuple[dict[str, Any], dict[str, str]]:
    """Build a master with two teams; return team A's instance's desired state (as sent)."""
    with running_app(config):
        team, other = create_team(SYSTEM, "Team A"), create_team(SYSTEM, "Team B")
        member, officer = make_user(Role.USER, team), make_user(Role.OFFICER)
        make_user(Role.USER, other)
        add_key(member, KEY, "laptop")
        open_task(team.id, name="Walking 1")
        open_task(other.id, name="Not theirs")
        update_world(SYSTEM, _moved_gate())  # version 2 on the master
        constellation = Constellation(
            name="ti-a", kind="cloudsim", provider="local", state=ConstellationState.READY
        )
        instance = TeamInstance(name="ti-a", team=team, constellation=constellation)
        db.session.add(instance)
        db.session.commit()
        state = json.loads(json.dumps(desired_state(instance)))
        return state, {"member": member.email, "officer": officer.email}


def test_desired_state_applies_once_and_puts_drift_back(
    make_config: Callable[..., Config], tmp_path: Path
) -> None:
    state, who = _master_state(make_config(instance_dir=tmp_path / "master"))
    assert [u["email"] for u in state["users"]] == [who["member"], who["officer"]]
    assert [t["name"] for t in state["tasks"]] == ["Walking 1"]  # not team B's
    with running_app(make_config(instance_dir=tmp_path / "instance")) as instance:
        master = token_for(make_user(Role.ADMIN))
        client = instance.test_client()
        first = client.put(DESIRED, json=state, headers=master)
        assert first.status_code == 200, first.get_json()
        assert f"user {who['member']} created" in first.get_json()["changed"]
        assert client.put(DESIRED, json=state, headers=master).get_json()["changed"] == []

        member = db.session.scalar(select(User).where(User.email == who["member"]))
        assert member is not None and member.team is not None
        assert member.team.name == "Team A" and [k.public_key for k in member.ssh_keys] == [KEY]
        _logs_in(instance, who["member"])  # the master's password, through the login form

        # Drift by hand on the instance: put back (the member) or reported (a local task).
        local = open_task(member.team_id or 0, name="Made here")
        update_user(SYSTEM, member.id, role="officer")
        db.session.delete(member.ssh_keys[0])
        db.session.commit()
        answer = client.put(DESIRED, json=state, headers=master).get_json()
        assert any(c.startswith(f"user {who['member']}: ") for c in answer["changed"])
        assert any("SSH key" in c and "added" in c for c in answer["changed"])
        assert f"task 'Made here' ({local.id}) was made on this instance" in answer["reported"]
        db.session.expire_all()
        assert member.role == Role.USER and member.team is not None

        # Disabled on the master (or deleted: not listed): disabled here, sessions end.
        state["users"][0]["active"] = False
        state["tasks"] = []
        answer = client.put(DESIRED, json=state, headers=master).get_json()
        assert f"user {who['member']}: active" in answer["changed"]
        assert "task 'Walking 1' removed" in answer["changed"]
        db.session.expire_all()
        assert not member.active
        assert db.session.scalar(select(Task).where(Task.name == "Walking 1")) is None


def _moved_gate() -> dict[str, Any]:
    document = shipped_document("vrc_task_1")
    document["configs"]["2"]["objects"]["gate_1"]["pose"] = [22.5, 3.0, 0.0]
    return document


def test_worlds_reach_the_instance_once_and_drift_is_put_back(
    make_config: Callable[..., Config], tmp_path: Path
) -> None:
    state, _ = _master_state(make_config(instance_dir=tmp_path / "master"))
    sent = {w["name"]: w for w in state["worlds"]}
    assert sent["vrc_task_1"]["version"] == 2 and sent["vrc_task_2"]["version"] == 1
    with running_app(make_config(instance_dir=tmp_path / "instance")) as instance:
        admin = make_user(Role.ADMIN)
        master, client = token_for(admin), instance.test_client()
        first = client.put(DESIRED, json=state, headers=master).get_json()
        assert [c for c in first["changed"] if c.startswith("world")] == [
            "world vrc_task_1: version 2"  # the others were already the master's
        ]
        assert client.put(DESIRED, json=state, headers=master).get_json()["changed"] == []
        here = client.get("/api/v1/worlds/vrc_task_1", headers=master).get_json()
        assert here["version"] == 2 and here["digest"] == sent["vrc_task_1"]["digest"]
        assert here["document"]["configs"]["2"]["objects"]["gate_1"]["pose"] == [22.5, 3.0, 0.0]

        # changed by hand here: put back to the master's document and version
        update_world(admin, shipped_document("vrc_task_1"))
        db.session.commit()
        answer = client.put(DESIRED, json=state, headers=master).get_json()
        assert "world vrc_task_1: version 2" in answer["changed"]
        assert client.get("/api/v1/worlds/vrc_task_1", headers=master).get_json()["version"] == 2

        # a document that is not what its digest says, or that drcsim refuses: nothing changes
        tampered = json.loads(json.dumps(state))
        tampered["worlds"][0]["document"]["time_limit_s"] = 60
        tampered["tasks"] = []
        refused = client.put(DESIRED, json=tampered, headers=master)
        assert refused.status_code == 400 and "digest" in refused.get_json()["message"]
        tampered["worlds"][0]["document"]["objects"] = []
        refused = client.put(DESIRED, json=tampered, headers=master)
        assert refused.status_code == 400 and "invalid world" in refused.get_json()["message"]
        assert db.session.scalar(select(Task).where(Task.name == "Walking 1")) is not None


def test_only_admins_push_and_bad_input_changes_nothing(app: Flask) -> None:
    client = app.test_client()
    officer = token_for(make_user(Role.OFFICER))
    admin = token_for(make_user(Role.ADMIN))
    body = {"team": "Team A", "users": [], "tasks": []}
    assert client.put(DESIRED, json=body).status_code == 401
    assert client.put(DESIRED, json=body, headers=officer).status_code == 403
    bad = {
        "team": "Team A",
        "users": [
            {
                "email": "x@example.org",
                "name": "X",
                "role": "admin",  # a master never makes admins on an instance
                "active": True,
                "password_hash": "plain",
                "ssh_keys": [],
            }
        ],
        "tasks": [],
    }
    answer = client.put(DESIRED, json=bad, headers=admin)
    assert answer.status_code == 422 or answer.status_code == 400, answer.get_json()
    assert db.session.scalar(select(User).where(User.email == "x@example.org")) is None
    task = {
        "key": "m1",
        "name": "Walking 1",
        "world": "vrc_task_2",
        "run_config": 1,
        "window_start": "0001-01-01T00:00:00+05:00",  # before year 1 in UTC: 400, not a 500
        "window_stop": "2030-01-01T00:00:00+00:00",
        "time_zone": "UTC",
        "timeout_s": 1800,
        "latency_ms": 0,
        "uplink_bits": 1,
        "downlink_bits": 1,
        "order": 0,
    }
    early = client.put(DESIRED, json=dict(body, tasks=[task]), headers=admin)
    assert early.status_code == 400, early.get_json()
    assert "window_start" in str(early.get_json())
    assert client.get("/api/v1/instance/health", headers=officer).status_code == 403
    health = client.get("/api/v1/instance/health", headers=admin).get_json()
    assert health["database"] and health["queue"] and health["version"]


def _logs_in(app: Flask, email: str) -> None:
    """Log in on the instance's login form with the shared test password."""
    from tests.conftest import PASSWORD

    browser = app.test_client()
    token = csrf_token(browser.get("/login").get_data(as_text=True))
    answer = browser.post(
        "/login", data={"email": email, "password": PASSWORD, "csrf_token": token}
    )
    assert answer.status_code == 302, answer.get_data(as_text=True)


def test_a_master_takes_no_desired_state(app: Flask, team_a: Team) -> None:
    admin = token_for(make_user(Role.ADMIN))
    member = make_user(Role.USER, team_a)
    service.deploy(SYSTEM, name="team-a", provider="local", team_id=team_a.id)
    db.session.commit()
    empty = {"team": None, "users": [], "tasks": []}
    answer = app.test_client().put(DESIRED, json=empty, headers=admin)
    assert answer.status_code == 409 and "master" in answer.get_json()["message"]
    db.session.refresh(member)
    assert member.active  # an empty desired state would have disabled every user
