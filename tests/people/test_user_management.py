"""Role, team and active changes through the API and the Users page, with the rules."""

from __future__ import annotations

import re

import pytest
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.errors import Conflict, NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations import vpn
from cloudsim.models import AuditEvent, Constellation, ConstellationState, Job, Machine, Role, User
from cloudsim.people.service import create_team, delete_user, find_team, find_user, update_user
from provisioners.remote import pki
from tests.conftest import csrf_token, log_in, make_user, token_for


@pytest.fixture
def ready_vrc(app: Flask, people: dict[str, User | None]) -> Constellation:
    team = people["user_a"].team  # type: ignore[union-attr]
    constellation = Constellation(
        name="vrc-a", kind="vrc", provider="local", team_id=team.id, state=ConstellationState.READY
    )
    constellation.machines.append(
        Machine(name="router", role="router", private_ip="10.211.3.50", public_ip="198.18.0.7")
    )
    db.session.add(constellation)
    db.session.commit()
    return constellation


def _patch(app: Flask, actor: User | None, user_id: int, body: dict[str, object]) -> object:
    return app.test_client().patch(
        f"/api/v1/users/{user_id}",
        json=body,
        headers=token_for(actor),  # type: ignore[arg-type]
    )


def test_the_api_moves_a_user_to_another_team_and_revokes_their_vpn(
    app: Flask, people: dict[str, User | None], ready_vrc: Constellation
) -> None:
    user = people["user_a"]
    assert user is not None
    old_team = user.team_id
    vpn.vpn_bundle(user, ready_vrc)
    serial = vpn.client_certificate(ready_vrc, user)["serial"]
    team_b = people["user_b"].team_id  # type: ignore[union-attr]
    response = _patch(app, people["officer"], user.id, {"team_id": team_b})
    assert response.status_code == 200, response.get_data(as_text=True)  # type: ignore[attr-defined]
    assert response.json["team_id"] == team_b  # type: ignore[attr-defined]
    db.session.expire_all()
    assert db.session.get(User, user.id).team_id == team_b  # type: ignore[union-attr]
    material = vpn.server_material(ready_vrc)
    ca = pki.CertificateAuthority(material.ca_cert, vpn._ca(ready_vrc).key_pem)
    assert serial in pki.revoked_serials(material.crl, ca)
    job = db.session.scalar(select(Job).where(Job.kind == "constellation.refresh_access"))
    assert job is not None and job.target_id == ready_vrc.id
    event = db.session.scalar(select(AuditEvent).where(AuditEvent.action == "user.update"))
    assert event is not None and event.details["team"] == team_b
    assert event.details["old_team"] == old_team


def test_the_api_changes_roles_and_the_active_flag(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    assert user is not None
    promoted = _patch(app, people["admin"], user.id, {"role": "officer"})
    assert promoted.status_code == 200, promoted.get_data(as_text=True)  # type: ignore[attr-defined]
    assert promoted.json["role"] == "officer" and promoted.json["team_id"] is None  # type: ignore[attr-defined]
    team_a = people["user_b"].team_id  # type: ignore[union-attr]
    back = _patch(app, people["admin"], user.id, {"role": "user", "team_id": team_a})
    assert back.json["role"] == "user" and back.json["team_id"] == team_a  # type: ignore[attr-defined]
    off = _patch(app, people["officer"], user.id, {"active": False})
    assert off.status_code == 200 and off.json["active"] is False  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("actor", "target", "body", "status", "message"),
    [
        ("officer", "user_a", {"role": "officer"}, 403, "only admins"),
        ("officer", "admin", {"name": "x"}, 403, "only admins"),
        ("officer", "officer", {"active": False}, 403, ""),
        ("admin", "admin", {"role": "user"}, 403, "your own role"),
        ("admin", "user_a", {"team_id": None}, 400, "must belong to a team"),
        ("admin", "user_a", {"team_id": 999}, 404, "team 999 not found"),
        ("admin", "officer", {"team_id": 1}, 400, "do not belong to a team"),
        ("user_a", "user_a", {"role": "admin"}, 403, ""),
        ("user_a", "user_b", {"team_id": 1}, 404, "not found"),
    ],
)
def test_the_rules_hold_and_nothing_changes(
    app: Flask,
    people: dict[str, User | None],
    actor: str,
    target: str,
    body: dict[str, object],
    status: int,
    message: str,
) -> None:
    victim = people[target]
    assert victim is not None
    before = (victim.role, victim.team_id, victim.active, victim.name)
    response = _patch(app, people[actor], victim.id, body)
    assert response.status_code == status, response.get_data(as_text=True)  # type: ignore[attr-defined]
    assert message in response.json["message"]  # type: ignore[attr-defined]
    db.session.expire_all()
    again = db.session.get(User, victim.id)
    assert (again.role, again.team_id, again.active, again.name) == before  # type: ignore[union-attr]


def test_nobody_demotes_disables_or_deletes_the_last_admin(
    app: Flask, people: dict[str, User | None]
) -> None:
    admin = people["admin"]
    assert admin is not None
    other = make_user(Role.ADMIN)
    api = app.test_client()
    # With two admins, one may demote the other; then the last one stands, whoever asks.
    demoted = api.patch(
        f"/api/v1/users/{other.id}", json={"role": "officer"}, headers=token_for(admin)
    )
    assert demoted.status_code == 200, demoted.get_data(as_text=True)
    for change in (
        lambda: update_user(SYSTEM, admin.id, role="officer"),
        lambda: update_user(SYSTEM, admin.id, active=False),
        lambda: delete_user(SYSTEM, admin.id),
    ):
        with pytest.raises(Conflict, match="at least one active admin"):
            change()
        db.session.rollback()
    assert db.session.get(User, admin.id).role == Role.ADMIN  # type: ignore[union-attr]


def test_an_officer_moves_and_disables_a_user_from_the_users_page(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    assert user is not None
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get(f"/users/{user.id}").get_data(as_text=True)
    # The form offers what the user has now (it used to select no team at all).
    selected = re.findall(r"<option[^>]*\bselected\b[^>]*>([^<]*)</option>", page)
    assert selected == ["user", user.team.name]  # type: ignore[union-attr]
    team_b = people["user_b"].team_id  # type: ignore[union-attr]
    # What the browser sends when "active" is unticked: no 'active' field at all.
    response = client.post(
        f"/users/{user.id}",
        data={
            "csrf_token": csrf_token(page),
            "email": user.email,
            "name": "Moved",
            "role": "user",
            "team": str(team_b),
            "password": "",
        },
    )
    assert response.status_code == 302, response.get_data(as_text=True)
    db.session.expire_all()
    moved = db.session.get(User, user.id)
    assert moved is not None
    assert (moved.team_id, moved.active, moved.name) == (team_b, False, "Moved")


@pytest.mark.postgres
@pytest.mark.parametrize("ref", ["99999999999", "2147483648", "0" * 30 + "7", "\u00b2"])
def test_a_command_naming_a_team_or_user_by_an_impossible_id_is_told_none(
    any_db_app: Flask, ref: str
) -> None:
    create_team(SYSTEM, "Seven")  # id 1: "...7" must not reach it by an int() of any length
    for find in (find_team, find_user):
        with pytest.raises(NotFound):
            find(ref)  # PostgreSQL refused such ids with a DataError: a traceback in the CLI
