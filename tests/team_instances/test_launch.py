"""Launching constellations through team instances: the rules, the summary, the provider
settings kept encrypted on both sides; the API, page and CLI as the README shows them. No
instance is reached here (tests/team_instances/test_local_launch.py launches for real)."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from click.testing import Result
from flask import Flask
from sqlalchemy import select, text
from werkzeug.datastructures import FileStorage, MultiDict
from werkzeug.test import encode_multipart

from cloudsim.auth.policy import SYSTEM
from cloudsim.errors import Forbidden, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import AuditEvent, InstanceState, Job, Role, Team, TeamInstance
from cloudsim.providers.service import provider_settings
from cloudsim.team_instances import launch, service
from cloudsim.team_instances.forms import MAX_INVENTORY_BYTES
from tests.competition.test_cli import run  # noqa: F401 (the fixture)
from tests.conftest import csrf_token, log_in, make_user, token_for
from tests.provisioners.providers.servers.keys import make_key_pair

KEY = make_key_pair("inventory")


def inventory(name: str = "srv-1") -> list[dict[str, object]]:
    return [
        {
            "name": name,
            "address": "198.18.0.7",
            "private_ip": "10.9.0.7",
            "public_ip": "198.18.0.7",
            "network": "lan",
            "cidr": "10.9.0.0/24",
            "private_key": KEY.private,
        }
    ]


def _ready(team: Team, name: str) -> TeamInstance:
    ((instance, _),) = service.deploy(SYSTEM, name=name, provider="local", team_id=team.id)
    instance.state = InstanceState.READY
    return instance


def test_rules_summary_and_settings_kept_encrypted(app: Flask, team_a: Team, team_b: Team) -> None:
    officer = make_user(Role.OFFICER)
    ours = _ready(team_a, "team-a")
    ((theirs, _),) = service.deploy(SYSTEM, name="team-b", provider="local", team_id=team_b.id)
    service.deploy(SYSTEM, name="spare", provider="local")  # no team: not in "every team"
    with pytest.raises(Forbidden):
        launch.launch(officer, "vrc", "servers")
    with pytest.raises(Forbidden):
        launch.set_provider_settings(officer, ours.id, "servers", {"inventory": inventory()})
    with pytest.raises(InvalidInput, match="kind"):
        launch.launch(SYSTEM, "nonsense", "servers")
    with pytest.raises(InvalidInput, match="provider"):
        launch.launch(SYSTEM, "vrc", "nowhere")
    with pytest.raises(InvalidInput, match="servers inventory"):
        launch.set_provider_settings(SYSTEM, ours.id, "servers", {"inventory": [{"name": "x"}]})
    with pytest.raises(InvalidInput, match="takes no settings"):
        launch.set_provider_settings(SYSTEM, ours.id, "local", {})

    summary = {o.instance: o for o in launch.launch(SYSTEM, "vrc", "servers")}
    assert set(summary) == {"team-a", "team-b"}
    assert summary["team-a"].state == "failed" and "no servers settings" in (
        summary["team-a"].why or ""
    )
    assert summary["team-b"].why == "the instance is deploying"
    assert ours.launch is None and theirs.launch is None  # nothing recorded for a refusal
    assert db.session.scalar(select(Job).where(Job.kind == launch.LAUNCH_JOB)) is None

    launch.set_provider_settings(SYSTEM, "team-a", "servers", {"inventory": inventory()})
    db.session.commit()
    stored = db.session.execute(text("SELECT value FROM secrets")).scalars().all()
    assert stored and not any("PRIVATE KEY" in v or "srv-1" in v for v in stored)
    (first,) = launch.launch(SYSTEM, "vrc", "servers", [ours.id])
    assert (first.state, first.team) == ("launching", "Team A") and first.job_id
    assert ours.launch == {"kind": "vrc", "provider": "servers", "state": "starting"}
    (again,) = launch.launch(SYSTEM, "vrc", "servers", ["team-a"])  # not launched twice
    assert again.state == "launching" and again.job_id is None
    db.session.commit()
    assert len(db.session.scalars(select(Job).where(Job.kind == launch.LAUNCH_JOB)).all()) == 1
    events = db.session.scalars(
        select(AuditEvent).where(AuditEvent.action.like("team_instance.%"))
    ).all()
    assert {"team_instance.provider", "team_instance.launch"} <= {e.action for e in events}
    assert not any(KEY.private[40:80] in json.dumps(e.details) for e in events)

    ours.launch = {"kind": "vrc", "state": "error", "error": "no free server"}
    (failed,) = launch.launch(SYSTEM, "vrc", "servers", [ours.id])  # a failed one: again
    assert failed.state == "launching" and failed.job_id


def test_api_and_page_as_the_readme_shows_them(app: Flask, team_a: Team) -> None:
    admin, officer = make_user(Role.ADMIN), make_user(Role.OFFICER)
    ours = _ready(team_a, "team-a")
    db.session.commit()
    client = app.test_client()
    body = {"provider": "servers", "settings": {"inventory": inventory()}}
    url = f"/api/v1/team-instances/{ours.id}/provider"
    assert client.put(url, json=body, headers=token_for(officer)).status_code == 403
    bad = client.put(url, json={"provider": "servers", "settings": {}}, headers=token_for(admin))
    assert bad.status_code == 400 and "inventory" in bad.get_json()["message"]
    answer = client.put(url, json=body, headers=token_for(admin))
    assert answer.status_code == 200 and KEY.private not in answer.get_data(as_text=True)
    launched = client.post(
        "/api/v1/team-instances/launch",
        json={"kind": "simple", "provider": "servers"},
        headers=token_for(officer),
    )
    assert launched.status_code == 403
    launched = client.post(
        "/api/v1/team-instances/launch",
        json={"kind": "simple", "provider": "servers", "instance_ids": [ours.id]},
        headers=token_for(admin),
    )
    assert launched.status_code == 200, launched.get_json()
    ((row),) = launched.get_json()
    assert (row["instance"], row["team"], row["state"]) == ("team-a", "Team A", "launching")
    shown = client.get(f"/api/v1/team-instances/{ours.id}", headers=token_for(admin)).get_json()
    assert shown["launch"]["kind"] == "simple" and shown["launch"]["state"] == "starting"

    # The page's button, really submitted: every team's, with the summary shown.
    log_in(client, admin)
    page = client.get("/team-instances").get_data(as_text=True)
    assert page.count("Launch for every team") == 1  # the form, once, in the page's body
    assert page.count('id="provider"') == 1  # the deploy form's: each label finds its field
    form = {"csrf_token": csrf_token(page), "kind": "simple", "provider": "servers"}
    answer = client.post("/team-instances/launch", data=form, follow_redirects=True)
    assert answer.status_code == 200
    assert "team-a (Team A): launching" in answer.get_data(as_text=True)
    refused = client.post("/team-instances/launch", data={**form, "kind": "nonsense"})
    assert refused.status_code == 400


def test_the_instance_page_form_keeps_settings_and_refuses_a_bad_inventory(
    app: Flask, team_a: Team
) -> None:
    admin = make_user(Role.ADMIN)
    ours = _ready(team_a, "team-a")
    db.session.commit()
    refused = launch.launch(SYSTEM, "vrc", "servers", [ours.id])
    assert "no servers settings" in (refused[0].why or "")
    client = app.test_client()
    log_in(client, admin)
    url = f"/team-instances/{ours.id}"
    page = client.get(url).get_data(as_text=True)
    assert "none kept" in page and "Keep settings" in page
    form = {"csrf_token": csrf_token(page), "provider": "servers"}

    # a bad inventory, pasted: the API's error, nothing kept
    bad = client.post(url + "/provider", data={**form, "inventory_text": "- name: x\n"})
    assert bad.status_code == 400 and "servers inventory" in bad.get_data(as_text=True)
    not_yaml = client.post(url + "/provider", data={**form, "inventory_text": "a: [b"})
    assert not_yaml.status_code == 400 and "not YAML" in not_yaml.get_data(as_text=True)
    # a file over the limit is refused, not cut short and parsed
    padded = yaml.safe_dump(inventory()).encode() + b"#" * MAX_INVENTORY_BYTES
    fields = {**form, "inventory_file": FileStorage(io.BytesIO(padded), "servers.yaml")}
    boundary, body = encode_multipart(MultiDict(fields))  # in memory: no temporary file left open
    too_big = client.post(
        url + "/provider", data=body, content_type=f"multipart/form-data; boundary={boundary}"
    )
    assert too_big.status_code == 400 and "at most 1024 KiB" in too_big.get_data(as_text=True)
    assert launch.kept_settings(ours.id) == {}
    # the form without its CSRF token: refused too
    assert client.post(url + "/provider", data={"provider": "servers"}).status_code == 400

    # a valid inventory, uploaded as a file
    upload = (io.BytesIO(yaml.safe_dump(inventory()).encode()), "servers.yaml")
    answer = client.post(
        url + "/provider",
        data={**form, "inventory_file": upload},
        content_type="multipart/form-data",
        follow_redirects=True,
    )
    shown = answer.get_data(as_text=True)
    assert answer.status_code == 200 and "servers settings kept (encrypted)" in shown
    assert "servers: kept (encrypted), set 20" in shown
    assert KEY.private[40:80] not in shown and "198.18.0.7" not in shown
    stored = db.session.execute(text("SELECT value FROM secrets")).scalars().all()
    assert stored and not any("PRIVATE KEY" in v or "srv-1" in v for v in stored)
    assert set(launch.kept_settings(ours.id)) == {"servers"}
    event = db.session.scalars(
        select(AuditEvent).where(AuditEvent.action == "team_instance.provider")
    ).one()
    assert event.details.get("provider") == "servers"
    (launched,) = launch.launch(SYSTEM, "vrc", "servers", [ours.id])
    assert launched.state == "launching" and launched.job_id

    # ec2: the fields `cloudsim provider configure ec2` takes
    ec2 = {**form, "provider": "ec2", "region": "us-east-1", "access_key": "AKIA", "image": "ami-1"}
    missing = client.post(url + "/provider", data=ec2)
    assert missing.status_code == 400 and "ec2 needs secret_key" in missing.get_data(as_text=True)
    ec2["secret_key"] = "s3cr3t"
    bad = client.post(url + "/provider", data={**ec2, "sizes": "gpu=g4\ncpu"})
    assert bad.status_code == 400 and "is not LOGICAL=TYPE" in bad.get_data(as_text=True)
    assert set(launch.kept_settings(ours.id)) == {"servers"}
    kept = client.post(url + "/provider", data={**ec2, "sizes": "gpu=g4\n\n"})
    assert kept.status_code == 302 and set(launch.kept_settings(ours.id)) == {"servers", "ec2"}
    page = client.get(url).get_data(as_text=True)
    assert "ec2: kept (encrypted)" in page and "s3cr3t" not in page


def test_an_instance_keeps_provider_settings_its_master_hands_it(app: Flask) -> None:
    admin, officer = make_user(Role.ADMIN), make_user(Role.OFFICER)
    client = app.test_client()
    body = {"settings": {"inventory": inventory()}}
    assert (
        client.put("/api/v1/providers/servers", json=body, headers=token_for(officer)).status_code
        == 403
    )
    bad = client.put(
        "/api/v1/providers/servers", json={"settings": {"x": 1}}, headers=token_for(admin)
    )
    assert bad.status_code == 400
    local = client.put("/api/v1/providers/local", json={"settings": {}}, headers=token_for(admin))
    assert local.status_code == 400 and "takes no settings" in local.get_json()["message"]
    with pytest.raises(InvalidInput, match="not configured"):
        provider_settings("servers")  # nothing stored by the refusals
    answer = client.put("/api/v1/providers/servers", json=body, headers=token_for(admin))
    assert answer.get_json() == {"name": "servers", "configured": True}
    assert provider_settings("servers") == body["settings"]
    event = db.session.scalars(
        select(AuditEvent).where(AuditEvent.action == "provider.configure")
    ).one()
    assert event.target_id == "servers" and "PRIVATE" not in json.dumps(event.details)


def test_cli_as_the_readme_shows_it(
    run: Callable[..., Result],  # noqa: F811 (`cloudsim` on a database `db upgrade` made)
    tmp_path: Path,
) -> None:
    def cli(*args: str, code: int = 0) -> str:
        result = run(*args)
        assert result.exit_code == code, result.output
        return result.output

    servers = tmp_path / "servers.yaml"
    servers.write_text(yaml.safe_dump(inventory()))
    cli("team", "create", "Team 8")
    cli("instance", "deploy", "--name", "team-8", "--team", "Team 8")
    assert "kept (encrypted)" in cli(
        "instance", "provider", "team-8", "servers", "--inventory", str(servers)
    )
    # an inventory sets up servers only: ec2 is not offered (its fields: the page or the API)
    refused = cli("instance", "provider", "team-8", "ec2", code=2)
    assert "'ec2' is not 'servers'" in refused
    (row,) = json.loads(cli("instance", "launch", "team-8", "--kind", "vrc", "--wait", "--json"))
    assert (row["instance"], row["state"], row["why"]) == (
        "team-8",
        "failed",
        "the instance is deploying",
    )
    assert json.loads(cli("instance", "launch", "--all", "--json"))[0]["why"] == row["why"]
    assert "name instances or give --all" in cli("instance", "launch", code=2)
