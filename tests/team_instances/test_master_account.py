"""On a team instance the master's word is final: a hand-made admin is put back (and the drift
shown on the master's page, API and audit log), the master's own account and token cannot be
taken away from the instance (page, API, CLI), `cloudsim instance restore-access --here`
gives them back when they were lost anyway, and a restarted instance serves no login before
its master has sent the current accounts."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from click.testing import CliRunner
from sqlalchemy import select

from cloudsim.auth.master import note_started, restore_master_access
from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Role,
    TeamInstance,
    User,
)
from cloudsim.people.service import create_team
from cloudsim.team_instances.sync import desired_state, synced
from tests.conftest import PASSWORD, csrf_token, log_in, make_user, running_app, token_for
from tests.support.servers import RedisServer
from tests.team_instances.test_sync import DESIRED

MASTER_EMAIL = "admin@example.org"
MASTER_TOKEN = "cst_the-masters-token-on-this-instance-0123456789"
MASTER = {"Authorization": f"Bearer {MASTER_TOKEN}"}


def _instance_config(make_config: Callable[..., Config], folder: Path) -> Config:
    return make_config(instance_dir=folder, admin_email=MASTER_EMAIL, admin_token=MASTER_TOKEN)


def test_a_hand_made_admin_is_put_back_and_the_drift_shown_on_the_master(
    make_config: Callable[..., Config], tmp_path: Path
) -> None:
    on_master = make_config(instance_dir=tmp_path / "master")
    on_instance = _instance_config(make_config, tmp_path / "instance")
    with running_app(on_master) as master:
        team = create_team(SYSTEM, "Team A")
        member = make_user(Role.USER, team)
        constellation = Constellation(
            name="ti-a", kind="cloudsim", provider="local", state=ConstellationState.READY
        )
        instance = TeamInstance(name="ti-a", team=team, constellation=constellation)
        db.session.add(instance)
        db.session.commit()
        state = json.loads(json.dumps(desired_state(instance)))
        answers: list[dict[str, Any]] = []
        with running_app(on_instance) as team_instance:
            restore_master_access(MASTER_EMAIL, MASTER_TOKEN)  # as `cloudsim up` does
            db.session.commit()
            client = team_instance.test_client()
            first = client.put(DESIRED, json=state, headers=MASTER).get_json()
            assert f"user {member.email} created" in first["changed"] and first["drift"] == []
            # As in the report: the member made an admin by hand, with the documented call;
            # and a new admin account made here.
            here = db.session.scalar(select(User).where(User.email == member.email))
            assert here is not None
            made = client.patch(f"/api/v1/users/{here.id}", json={"role": "admin"}, headers=MASTER)
            assert made.status_code == 200, made.get_json()
            local = make_user(Role.ADMIN)
            local_token = token_for(local)
            answer = client.put(DESIRED, json=state, headers=MASTER).get_json()
            answers.append(answer)
            assert f"user {member.email}: role, team_id" in answer["drift"], answer
            assert f"user {local.email} (admin) disabled: made here" in answer["drift"], answer
            db.session.expire_all()
            assert here.role == Role.USER and here.team is not None
            assert here.team.name == "Team A" and not local.active
            assert client.get("/api/v1/me", headers=local_token).status_code == 401
            # in sync again: nothing more to put back
            again = client.put(DESIRED, json=state, headers=MASTER).get_json()
            assert again["changed"] == [] and again["drift"] == []
        # The master records the instance's answer (as its sync job or reconcile does).
        instance = db.session.get(TeamInstance, instance.id)
        assert instance is not None
        synced(instance, answers[0])
        db.session.commit()
        admin = make_user(Role.ADMIN)
        client = master.test_client()
        shown = client.get(f"/api/v1/team-instances/{instance.id}", headers=token_for(admin))
        assert f"user {member.email}: role, team_id" in shown.get_json()["sync_report"]["drift"]
        audit = client.get(
            "/api/v1/audit?action=team_instance.drift", headers=token_for(admin)
        ).get_json()
        assert audit and audit[0]["target_id"] == str(instance.id)
        assert f"user {member.email}: role, team_id" in audit[0]["details"]["put_back"]
        log_in(client, admin)
        page = client.get(f"/team-instances/{instance.id}").get_data(as_text=True)
        assert "Drift put back" in page and f"user {member.email}: role, team_id" in page
        assert "(drift put back)" in page


def test_the_masters_account_and_token_cannot_be_taken_away_on_the_instance(
    make_config: Callable[..., Config], tmp_path: Path
) -> None:
    with running_app(_instance_config(make_config, tmp_path / "instance")) as app:
        restore_master_access(MASTER_EMAIL, MASTER_TOKEN)
        db.session.commit()
        master = db.session.scalar(select(User).where(User.email == MASTER_EMAIL))
        assert master is not None
        other = make_user(Role.ADMIN)  # an admin made here, as the report's team did
        theirs = token_for(other)
        client = app.test_client()
        for body in ({"active": False}, {"role": "officer"}, {"role": "user", "team_id": 1}):
            refused = client.patch(f"/api/v1/users/{master.id}", json=body, headers=theirs)
            assert refused.status_code == 409, (body, refused.get_json())
            assert "master manages" in refused.get_json()["message"]
        refused = client.delete(f"/api/v1/users/{master.id}", headers=theirs)
        assert refused.status_code == 409 and "cannot be deleted" in refused.get_json()["message"]
        tokens = client.get("/api/v1/tokens", headers=MASTER).get_json()
        [token_id] = [t["id"] for t in tokens if t["name"] == "master"]
        refused = client.delete(f"/api/v1/tokens/{token_id}", headers=MASTER)
        assert refused.status_code == 409 and "cannot be revoked" in refused.get_json()["message"]

        # The user page's form, really submitted: the account is not disabled.
        log_in(client, other)
        form = client.get(f"/users/{master.id}").get_data(as_text=True)
        data = {"csrf_token": csrf_token(form), "email": MASTER_EMAIL, "name": "Admin"}
        answer = client.post(f"/users/{master.id}", data=data | {"role": "admin", "team": ""})
        assert answer.status_code == 409 and "master manages" in answer.get_data(as_text=True)
        db.session.expire_all()
        assert master.active and master.role == Role.ADMIN
        assert client.get("/api/v1/me", headers=MASTER).get_json()["email"] == MASTER_EMAIL

        # A restarted instance: no login but the master's until the master has synced.
        note_started(app.config["CLOUDSIM"])
        waiting = app.test_client()
        page = waiting.get("/login").get_data(as_text=True)
        answer = waiting.post(
            "/login",
            data={"email": other.email, "password": PASSWORD, "csrf_token": csrf_token(page)},
        )
        assert answer.status_code == 503
        assert "has not heard from its master yet" in answer.get_data(as_text=True)
        assert client.get("/api/v1/me", headers=theirs).status_code == 503
        assert client.get(f"/users/{master.id}").status_code == 302  # its session waits too
        assert client.get("/api/v1/me", headers=MASTER).status_code == 200
        empty = {"team": None, "users": [], "tasks": []}
        assert client.put(DESIRED, json=empty, headers=MASTER).status_code == 200
        # the master listed no one: the hand-made admin is disabled, logins are open again
        assert client.get("/api/v1/me", headers=theirs).status_code == 401
        assert app.test_client().get("/login").status_code == 200


def test_the_cli_refuses_and_restore_access_gives_the_master_back_its_access(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str
) -> None:
    env: dict[str, str | None] = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_ARGON2_TIME_COST": "1",
        "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
        "CLOUDSIM_ADMIN_EMAIL": MASTER_EMAIL,
        "CLOUDSIM_ADMIN_TOKEN": MASTER_TOKEN,
    }

    def cli(*args: str, settings: dict[str, str | None] = env) -> tuple[int, str]:
        result = CliRunner().invoke(main, list(args), env=settings)
        return result.exit_code, result.output

    assert cli("db", "upgrade")[0] == 0
    code, out = cli("instance", "restore-access", "--here")
    assert code == 0 and f"account {MASTER_EMAIL} created" in out, out
    assert "the master's token issued" in out
    code, out = cli("instance", "restore-access", "--here")
    assert (code, out.strip()) == (0, "the master's access was whole")
    code, out = cli("user", "update", MASTER_EMAIL, "--inactive")
    assert code == 1 and "master manages" in out, out
    code, out = cli("user", "update", MASTER_EMAIL, "--role", "officer")
    assert code == 1 and "master manages" in out, out

    # Lost anyway: the same database changed by a CloudSim that is not this instance (as a
    # restored backup, or someone with root on the machine, would leave it).
    bare = env | {"CLOUDSIM_ADMIN_TOKEN": None}
    made = cli("user", "create", "--email", "other@example.org", "--role", "admin", settings=bare)
    assert made[0] == 0, made
    code, out = cli(
        "user", "update", MASTER_EMAIL, "--inactive", "--role", "officer", settings=bare
    )
    assert code == 0, out  # disabling also revoked every token of the account
    code, out = cli("instance", "restore-access", "--here")
    assert code == 0, out
    for restored in ("made an admin again", "enabled", "the master's token un-revoked"):
        assert restored in out, out
    assert cli("instance", "restore-access")[0] == 2  # neither a name nor --here: usage
