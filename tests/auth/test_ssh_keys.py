"""Users' SSH keys: validation with reasons, the account page's form, the API, the CLI, the push."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ec, ed25519, rsa
from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.ssh_keys import parse_public_key
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.launched_constellations.access import team_members
from cloudsim.launched_constellations.service import launch
from cloudsim.models import Constellation, Job, Role, SshKey, User
from cloudsim.people.service import update_user
from tests.competition.support import ready_constellation
from tests.conftest import csrf_token, log_in, make_user, token_for


def pushed_keys(team_id: int | None) -> tuple[str, ...]:
    """Return the keys the access refresh writes on the field computers, every member's."""
    return tuple(key for member in team_members(team_id) for key in member.keys)


def openssh(key: object, comment: str = "pat@laptop") -> str:
    """Return a public key line as ssh-keygen writes it."""
    text = key.public_key().public_bytes(  # type: ignore[attr-defined]
        serialization.Encoding.OpenSSH, serialization.PublicFormat.OpenSSH
    )
    return f"{text.decode()} {comment}"


def keygen_fingerprint(line: str, tmp_path: Path) -> str:
    """Return what ssh-keygen -l says the key's fingerprint is."""
    path = tmp_path / "key.pub"
    path.write_text(line + "\n")
    out = subprocess.run(["ssh-keygen", "-l", "-f", str(path)], capture_output=True, text=True)
    return out.stdout.split()[1]


@pytest.mark.parametrize(
    "make",
    [
        ed25519.Ed25519PrivateKey.generate,
        lambda: ec.generate_private_key(ec.SECP256R1()),
        lambda: ec.generate_private_key(ec.SECP384R1()),
        lambda: rsa.generate_private_key(65537, 3072),
    ],
    ids=["ed25519", "ecdsa-256", "ecdsa-384", "rsa-3072"],
)
def test_strong_keys_are_accepted_with_ssh_keygens_fingerprint(
    make: object, tmp_path: Path
) -> None:
    line = openssh(make())  # type: ignore[operator]
    parsed = parse_public_key(line)
    assert parsed.fingerprint == keygen_fingerprint(line, tmp_path)
    assert parsed.comment == "pat@laptop" and parsed.public_key == " ".join(line.split()[:2])


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        (openssh(rsa.generate_private_key(65537, 2048)), "2048 bits; at least 3072"),
        ("ssh-dss AAAAB3NzaC1kc3MAAACBAP pat", "DSA keys are too weak"),
        ("ssh-ed25519 AAAA!!notbase64 pat", "malformed"),
        ("ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIOJj8kvFrXnlIYn6", "malformed"),
        ("ssh-ed25519", "TYPE BASE64"),
        ('from="10.0.0.1" ssh-ed25519 AAAAC3Nz pat', "unsupported key type"),
        ("sk-ssh-ed25519@openssh.com AAAAGnNrLXNzaC1lZDI1NTE5QG9wZW5zc2guY29t", "unsupported"),
        ("-----BEGIN OPENSSH PRIVATE KEY-----\nb3BlbnNzaC1rZXk=\n-----END", "private key"),
        ("", "exactly one public key"),
    ],
    ids=["rsa-2048", "dsa", "base64", "cut", "no-data", "options", "sk", "private", "empty"],
)
def test_weak_or_malformed_keys_are_refused_with_the_reason(text: str, reason: str) -> None:
    with pytest.raises(InvalidInput, match=reason):
        parse_public_key(text)


def _ready_vrc(team_id: int) -> Constellation:
    """Launch one (no worker takes the job) and mark it ready, as its launch would."""
    constellation, _ = launch(
        SYSTEM, name=f"keys{team_id}", kind="vrc", provider="local", team_id=team_id
    )
    db.session.commit()
    ready_constellation(constellation.id)
    return constellation


def _refreshes(constellation: Constellation) -> int:
    db.session.expire_all()
    return len(
        db.session.scalars(
            select(Job).where(
                Job.kind == "constellation.refresh_access", Job.target_id == constellation.id
            )
        ).all()
    )


def test_the_account_form_adds_a_key_and_the_team_computers_get_it(
    app: Flask, client: FlaskClient, people: dict[str, User | None]
) -> None:
    """As a stranger would: the account page's form, really submitted."""
    user = people["user_a"]
    assert user is not None and user.team_id is not None
    constellation = _ready_vrc(user.team_id)
    log_in(client, user)
    page = client.get("/account").get_data(as_text=True)
    line = openssh(ed25519.Ed25519PrivateKey.generate())
    response = client.post(
        "/account/ssh-keys",
        data={"csrf_token": csrf_token(page), "name": "laptop", "public_key": line},
    )
    assert response.status_code == 302
    page = client.get("/account").get_data(as_text=True)
    fingerprint = parse_public_key(line).fingerprint
    assert fingerprint in page and "laptop" in page
    assert pushed_keys(user.team_id) == (f"{' '.join(line.split()[:2])} {user.email}",)
    assert _refreshes(constellation) == 1  # pushed to the field computers at once
    # a weak key: the reason on the form, nothing stored
    weak = openssh(rsa.generate_private_key(65537, 2048))
    response = client.post(
        "/account/ssh-keys", data={"csrf_token": csrf_token(page), "public_key": weak}
    )
    assert response.status_code == 400 and "at least 3072" in response.get_data(as_text=True)
    assert len(db.session.scalars(select(SshKey)).all()) == 1


def test_a_generated_key_is_shown_once_kept_public_and_removed_from_the_page(
    app: Flask, client: FlaskClient, people: dict[str, User | None]
) -> None:
    """As a stranger would: "Make a key for me", then the key's "Remove" button."""
    user = people["user_a"]
    assert user is not None and user.team_id is not None
    constellation = _ready_vrc(user.team_id)
    log_in(client, user)
    page = client.get("/account").get_data(as_text=True)
    # what the browser sends for that button: the form's (empty) fields and the button's value
    response = client.post(
        "/account/ssh-keys",
        data={"csrf_token": csrf_token(page), "name": "", "public_key": "", "generate": "1"},
    )
    html = response.get_data(as_text=True)
    assert response.status_code == 200 and "BEGIN OPENSSH PRIVATE KEY" in html
    assert 'download="cloudsim_ed25519"' in html
    page = client.get("/account").get_data(as_text=True)
    assert "PRIVATE KEY" not in page
    [stored] = db.session.scalars(select(SshKey)).all()
    assert stored.key_type == "ssh-ed25519" and "PRIVATE" not in stored.public_key
    assert len(pushed_keys(user.team_id)) == 1
    before = _refreshes(constellation)
    [action] = re.findall(r'<form class="inline" method="post" action="([^"]+/delete)"', page)
    response = client.post(action, data={"csrf_token": csrf_token(page)})
    assert response.status_code == 302
    assert "No SSH keys." in client.get("/account").get_data(as_text=True)
    assert pushed_keys(user.team_id) == () and _refreshes(constellation) == before + 1


def test_the_api_adds_lists_generates_and_deletes_own_keys_only(
    app: Flask, people: dict[str, User | None]
) -> None:
    user, other = people["user_a"], people["user_b"]
    assert user is not None and other is not None
    client, headers = app.test_client(), token_for(user)
    line = openssh(ec.generate_private_key(ec.SECP256R1()))
    created = client.post("/api/v1/me/ssh-keys", json={"public_key": line}, headers=headers)
    assert created.status_code == 201, created.get_json()
    body = created.get_json()
    assert body["fingerprint"].startswith("SHA256:") and body["bits"] == 256
    assert "private_key" not in body
    again = client.post("/api/v1/me/ssh-keys", json={"public_key": line}, headers=headers)
    assert again.status_code == 400 and "already added" in again.get_json()["message"]
    made = client.post("/api/v1/me/ssh-keys", json={"generate": True}, headers=headers)
    assert made.status_code == 201 and "PRIVATE KEY" in made.get_json()["private_key"]
    listed = client.get("/api/v1/me/ssh-keys", headers=headers).get_json()
    assert [k["id"] for k in listed] == [body["id"], made.get_json()["id"]]
    assert all("private_key" not in k for k in listed)
    stranger = client.delete(f"/api/v1/me/ssh-keys/{body['id']}", headers=token_for(other))
    assert stranger.status_code == 404
    gone = client.delete(f"/api/v1/me/ssh-keys/{body['id']}", headers=headers)
    assert gone.status_code == 204
    bad = client.post("/api/v1/me/ssh-keys", json={"public_key": "ssh-rsa AAAA"}, headers=headers)
    assert bad.status_code == 400 and "malformed" in bad.get_json()["message"]


def test_only_active_members_keys_reach_the_team_account(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    assert user is not None and user.team_id is not None
    team_id = user.team_id
    constellation = _ready_vrc(team_id)
    teammate = make_user(Role.USER, user.team)
    client = app.test_client()
    for member in (user, teammate):
        line = openssh(ed25519.Ed25519PrivateKey.generate())
        client.post("/api/v1/me/ssh-keys", json={"public_key": line}, headers=token_for(member))
    assert len(pushed_keys(team_id)) == 2
    before = _refreshes(constellation)
    update_user(SYSTEM, teammate.id, active=False)  # one hook: VPN and SSH keys
    db.session.commit()
    assert len(pushed_keys(team_id)) == 1 and _refreshes(constellation) == before + 1
    update_user(SYSTEM, teammate.id, active=True)  # back: their key again
    db.session.commit()
    assert len(pushed_keys(team_id)) == 2 and _refreshes(constellation) == before + 2
