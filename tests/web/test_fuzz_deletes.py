"""Every DELETE the OpenAPI document offers, aimed at objects with real histories.

The schema fuzzer draws ids at random and seldom hits a row that has a past; this one takes
each DELETE operation of the document and aims it, as an admin, at the object with the most
history of its kind: a team without members but with constellations and runs, a user who
started runs, a task that was run, a constellation with runs, a team instance, the caller's
token, key and webhook. Each answer is documented, never a 5xx; a 409 says why; a 2xx kept
the history (every run, its logs and the audit trail are still there, with their team).
Worlds have no DELETE: a world in use cannot be deleted at all.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.ssh_keys import add_key
from cloudsim.extensions import db
from cloudsim.models import (
    ApiToken,
    Artifact,
    AuditEvent,
    Constellation,
    ConstellationState,
    Run,
    Team,
    TeamInstance,
    User,
)
from cloudsim.people.service import create_team
from tests.competition.support import finished_run, open_task
from tests.conftest import token_for
from tests.web.fuzz import populate, watched_log

KEY = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIOMqqnkVzrm0SdG6UOoqKLsabgH5C9okWi0dh2l9GKJl"


def _past_team(tmp: Path) -> Team:
    """A team whose members left: a terminated constellation and a finished run stay."""
    team = create_team(SYSTEM, "Team Past")
    db.session.commit()
    gone = Constellation(
        name="past-vrc", kind="vrc", provider="local", team_id=team.id,
        state=ConstellationState.TERMINATED,
    )  # fmt: skip
    db.session.add(gone)
    db.session.commit()
    finished_run(open_task(team.id), gone.id, tmp)
    return team


def _targets(people: dict[str, User | None], tmp: Path) -> dict[str, Callable[[], int]]:
    """Return, per DELETE path of the document, how to find the object it is aimed at."""
    user_a, admin = people["user_a"], people["admin"]
    assert user_a is not None and admin is not None
    team = _past_team(tmp)
    run = db.session.scalars(select(Run).where(Run.team_id == user_a.team_id)).first()
    assert run is not None
    run.started_by_id = user_a.id
    live = db.session.scalars(
        select(Constellation).where(Constellation.state == ConstellationState.READY)
    ).first()
    assert live is not None
    instance = TeamInstance(name="ti-past", team_id=user_a.team_id, constellation_id=live.id)
    db.session.add(instance)
    key = add_key(admin, KEY, "laptop")
    db.session.commit()

    def own_token() -> int:
        return db.session.scalars(
            select(ApiToken.id).where(ApiToken.user_id == admin.id).order_by(ApiToken.id)
        ).first()  # type: ignore[return-value]

    def webhook() -> int:
        from cloudsim.models import Webhook

        hook = Webhook(url="https://hooks.example.org/cloudsim", secret="a webhook secret")
        db.session.add(hook)
        db.session.commit()
        return hook.id

    return {
        "/api/v1/teams/{team_id}": lambda: team.id,
        "/api/v1/users/{user_id}": lambda: user_a.id,
        "/api/v1/tasks/{task_id}": lambda: run.task_id,
        "/api/v1/constellations/{ref}": lambda: live.id,
        "/api/v1/team-instances/{instance_id}": lambda: instance.id,
        "/api/v1/tokens/{token_id}": own_token,
        "/api/v1/me/ssh-keys/{key_id}": lambda: key.id,
        "/api/v1/webhooks/{webhook_id}": webhook,
    }


def _history() -> dict[str, Any]:
    """Return what must survive any delete: each run with its team, logs and audit events."""
    db.session.expire_all()
    return {
        "runs": sorted(
            tuple(row) for row in db.session.execute(select(Run.id, Run.team_id, Run.task_id))
        ),
        "logs": db.session.scalar(select(func.count(Artifact.id))),
        "audit": set(db.session.scalars(select(AuditEvent.id))),
    }


def test_every_delete_on_an_object_with_a_history_is_refused_or_keeps_it(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    populate(app, people, tmp_path)
    admin = people["admin"]
    assert admin is not None
    headers = token_for(admin)
    spec = app.test_client().get("/api/v1/openapi.json").get_json()
    deletes = {path: item["delete"] for path, item in spec["paths"].items() if "delete" in item}
    targets = _targets(people, tmp_path)
    # a new DELETE route needs its object with a history here before it can ship
    assert set(deletes) == set(targets), set(deletes) ^ set(targets)
    client, answers = app.test_client(), {}
    with watched_log() as log:
        for path, operation in sorted(deletes.items()):
            before = _history()
            (name,) = re.findall(r"{(\w+)}", path)
            url = path.replace(f"{{{name}}}", str(targets[path]()))
            response = client.delete(url, headers=headers)
            status = response.status_code
            answers[path] = status
            assert status < 500, f"{url}: {status} {response.get_data(as_text=True)[:500]}"
            documented = operation["responses"]
            assert str(status) in documented or "default" in documented, f"{url}: {status}"
            if status == 409:
                message = (response.get_json() or {}).get("message", "")
                assert len(message) > 20, f"{url}: a 409 without its reason: {message!r}"
            after = _history()
            # every run keeps its team and task, every log its row, every audit event stays
            assert after["runs"] == before["runs"], url
            assert after["logs"] == before["logs"], url
            assert before["audit"] <= after["audit"], url
    assert not log.records, f"the app logged errors:\n{log.report()}"
    # the objects with a past are refused or kept: the team and the task were not deleted
    assert answers["/api/v1/teams/{team_id}"] == 409
    assert answers["/api/v1/tasks/{task_id}"] == 409
    db.session.expire_all()
    assert db.session.scalar(select(Team).where(Team.name == "Team Past")) is not None


@pytest.mark.parametrize("form", ["team", "user"])
def test_the_delete_forms_refuse_or_keep_a_history_too(
    app: Flask, people: dict[str, User | None], tmp_path: Path, form: str
) -> None:
    from tests.conftest import csrf_token, log_in

    populate(app, people, tmp_path)
    targets = _targets(people, tmp_path)
    target = targets["/api/v1/teams/{team_id}" if form == "team" else "/api/v1/users/{user_id}"]()
    admin = people["admin"]
    assert admin is not None
    client = app.test_client()
    log_in(client, admin)
    page = f"/{form}s/{target}"
    before = _history()
    with watched_log() as log:
        response = client.post(
            f"{page}/delete",
            data={"csrf_token": csrf_token(client.get(page).get_data(as_text=True))},
            follow_redirects=True,
        )
    assert response.status_code < 500, response.get_data(as_text=True)[:500]
    assert not log.records, log.report()
    after = _history()
    assert after["runs"] == before["runs"] and after["logs"] == before["logs"]
    if form == "team":
        assert "has a history" in response.get_data(as_text=True)
