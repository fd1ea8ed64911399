"""Each member's own field-computer account as the README promises it: named in their VPN
bundle's README and ssh_config (downloaded with the documented route) and on the
constellation's page; officers see every member's account; the accounts follow the team
(no hosts needed: test_team_access.py logs in as them)."""

from __future__ import annotations

import io
import zipfile
from threading import Thread

import pytest
from flask import Flask
from flask.testing import FlaskClient

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.launched_constellations.access import refresh_turn, team_members
from cloudsim.models import Constellation, ConstellationState, Machine, Role, SshKey, User
from cloudsim.people.service import update_user
from constellations.plans.base import MEMBER_UID_BASE, member_account_name
from tests.conftest import log_in, make_user, token_for


@pytest.fixture
def ready_vrc(app: Flask, people: dict[str, User | None]) -> Constellation:
    team = people["user_a"].team  # type: ignore[union-attr]
    constellation = Constellation(
        name="vrc-a", kind="vrc", provider="local", team_id=team.id, state=ConstellationState.READY
    )
    for n, (name, role) in enumerate(
        (("router", "router"), ("sim", "sim"), ("fc1", "fc"), ("fc2", "fc"))
    ):
        constellation.machines.append(
            Machine(name=name, role=role, private_ip=f"10.211.3.{50 + n}")
        )
    constellation.machines[0].public_ip = "198.18.0.7"
    db.session.add(constellation)
    db.session.commit()
    return constellation


def _account(user: User) -> str:
    return member_account_name(user.email, user.id)


def test_the_bundle_and_the_page_name_the_member_s_own_account(
    app: Flask,
    client: FlaskClient,
    people: dict[str, User | None],
    ready_vrc: Constellation,
) -> None:
    alice = people["user_a"]
    assert alice is not None
    bob = make_user(Role.USER, alice.team)
    response = app.test_client().get(
        f"/api/v1/constellations/{ready_vrc.id}/vpn-bundle", headers=token_for(alice)
    )
    assert response.status_code == 200
    readme = zipfile.ZipFile(io.BytesIO(response.data)).read("README.txt").decode()
    mine, theirs = _account(alice), _account(bob)
    assert mine != theirs and str(alice.id) in mine
    assert f"ssh {mine}@10.211.3.52" in readme and f"ssh {mine}@10.211.3.53" in readme
    assert f"User {mine}" in readme and "User team" not in readme and theirs not in readme
    log_in(client, alice)
    page = client.get(f"/constellations/{ready_vrc.id}").get_data(as_text=True)
    assert f'<span id="my-account">{mine}</span>' in page
    assert f"ssh {mine}@10.211.3.52" in page and f"User {mine}" in page
    assert theirs not in page  # a member sees their own account only


def test_an_officer_sees_every_member_s_account_and_a_placeholder_to_log_in_with(
    app: Flask,
    client: FlaskClient,
    people: dict[str, User | None],
    ready_vrc: Constellation,
) -> None:
    alice, officer = people["user_a"], people["officer"]
    assert alice is not None and officer is not None
    log_in(client, officer)
    page = client.get(f"/constellations/{ready_vrc.id}").get_data(as_text=True)
    assert f"(account <code>{_account(alice)}</code>)" in page
    assert "User YOUR_ACCOUNT" in page and 'id="my-account"' not in page


def test_accounts_follow_the_team_active_members_only_each_with_their_own_keys(
    app: Flask,
    people: dict[str, User | None],
    ready_vrc: Constellation,
) -> None:
    alice = people["user_a"]
    assert alice is not None
    bob = make_user(Role.USER, alice.team)
    key = "ssh-ed25519 AAAAbob"
    db.session.add(
        SshKey(user_id=bob.id, name="k", key_type="ssh-ed25519", bits=256, public_key=key,
               fingerprint="SHA256:b")
    )  # fmt: skip
    db.session.commit()
    members = {m.name: m for m in team_members(alice.team_id)}
    assert set(members) == {_account(alice), _account(bob)}
    assert members[_account(bob)].keys == (f"ssh-ed25519 AAAAbob {bob.email}",)
    assert members[_account(alice)].keys == () and members[_account(bob)].uid == (
        MEMBER_UID_BASE + bob.id
    )
    update_user(SYSTEM, bob.id, active=False)
    db.session.commit()
    assert [m.name for m in team_members(alice.team_id)] == [_account(alice)]


def test_refreshes_of_one_constellation_take_turns_others_run_at_once(app: Flask) -> None:
    entered: list[int] = []

    def refresh(constellation_id: int) -> None:
        with app.app_context(), refresh_turn(constellation_id):
            entered.append(constellation_id)

    with refresh_turn(4242):
        same, other = (Thread(target=refresh, args=(n,)) for n in (4242, 4243))
        same.start()
        other.start()
        other.join(30)
        assert entered == [4243]  # another constellation's refresh does not wait
        same.join(1)
        assert same.is_alive() and entered == [4243]  # this one waits for its turn
    same.join(30)
    assert entered == [4243, 4242]
