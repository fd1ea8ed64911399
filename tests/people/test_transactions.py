"""Services only flush: the request, command or job that calls them commits, or rolls back."""

from __future__ import annotations

from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.models import AuditEvent, Team
from cloudsim.people.service import create_team


def test_a_service_leaves_the_commit_to_its_caller(app: Flask) -> None:
    team = create_team(SYSTEM, "Flushed only")
    assert team.id is not None  # flushed: the id is known, the row is in this transaction
    db.session.rollback()  # the caller failed after the service returned
    assert db.session.scalar(select(Team).where(Team.name == "Flushed only")) is None
    assert db.session.scalar(select(AuditEvent)) is None  # nor the record of it


def test_cloudsim_itself_is_an_explicit_actor(app: Flask) -> None:
    create_team(SYSTEM, "By the system")
    db.session.commit()
    event = db.session.scalar(select(AuditEvent).where(AuditEvent.action == "team.create"))
    assert event is not None and event.actor == "system" and event.actor_id is None


def test_a_request_commits_its_success_and_nothing_of_a_refusal(app: Flask) -> None:
    """A view that shows its form again with a service's error commits nothing it flushed."""

    @app.post("/_test/team/<name>/<int:status>")
    def make_team(name: str, status: int) -> tuple[str, int]:
        create_team(SYSTEM, name)  # flushed, then the view answers with `status`
        return name, status

    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    refused = client.post("/_test/team/Refused/400")
    assert (refused.status_code, refused.get_data(as_text=True)) == (400, "Refused")
    assert client.post("/_test/team/Kept/201").status_code == 201
    db.session.remove()  # look with a fresh session: what did the requests commit?
    names = set(db.session.scalars(select(Team.name)))
    assert names == {"Kept"}
