"""World definitions on a CloudSim: seeded from drcsim, updated by admins (page, API, CLI)
after drcsim's check, versioned, audited; refusals change nothing; runs use the stored copy."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from click.testing import Result
from drcsim.worlds import WORLD_NAMES, document_digest, shipped_document
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import run_dir
from cloudsim.competition.jobs import simulator_command
from cloudsim.errors import Conflict, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import AuditEvent, Role, Run, RunState, Team, World
from cloudsim.worlds.service import check_world, update_world
from tests.competition.support import open_task
from tests.competition.test_cli import run  # noqa: F401 (the fixture)
from tests.conftest import csrf_token, log_in, make_user, token_for


def _moved_gate() -> dict:
    document = shipped_document("vrc_task_1")
    document["configs"]["2"]["objects"]["gate_1"]["pose"] = [22.5, 3.0, 0.0]
    return document


def _row(name: str = "vrc_task_1") -> World:
    db.session.expire_all()
    found = db.session.scalar(select(World).where(World.name == name))
    assert found is not None
    return found


def test_seeded_from_drcsim_and_versioned_by_content(app: Flask) -> None:
    assert [w.name for w in db.session.scalars(select(World).order_by(World.name))] == list(
        WORLD_NAMES
    )
    assert _row().digest == document_digest(shipped_document("vrc_task_1"))
    done = update_world(SYSTEM, _moved_gate())
    db.session.commit()
    assert done.changed and (_row().version, _row().digest) == (2, document_digest(_moved_gate()))
    # key order and spacing do not make a new version
    again = update_world(SYSTEM, json.loads(json.dumps(_moved_gate(), sort_keys=True)))
    assert not again.changed and _row().version == 2
    event = db.session.scalar(select(AuditEvent).where(AuditEvent.action == "world.update"))
    assert event is not None and event.target_id == "vrc_task_1"


def test_bad_documents_are_refused_and_change_nothing(app: Flask, team_a: Team) -> None:
    broken = _moved_gate()
    broken["checkpoints"][1]["when"]["through_gate"]["gate"] = "gate_9"
    with pytest.raises(InvalidInput, match="'gate_9' is not a gate of this world"):
        update_world(SYSTEM, broken)
    unknown = _moved_gate() | {"name": "vrc_task_9"}
    with pytest.raises(InvalidInput, match="unknown world 'vrc_task_9'"):
        update_world(SYSTEM, unknown)
    open_task(team_a.id, world="vrc_task_1", run_config=5)
    dropped = _moved_gate()
    del dropped["configs"]["5"]
    with pytest.raises(Conflict, match="uses vrc_task_1 run configuration 5"):
        update_world(SYSTEM, dropped)
    with pytest.raises(Exception, match="only admins"):
        update_world(make_user(Role.OFFICER), _moved_gate())
    db.session.rollback()
    assert _row().version == 1
    assert db.session.scalar(select(AuditEvent).where(AuditEvent.action == "world.update")) is None


def test_tasks_and_runs_use_the_stored_world(app: Flask, team_a: Team) -> None:
    document = _moved_gate()
    document["configs"]["6"] = {"seed": 1106}
    update_world(SYSTEM, document)
    db.session.commit()
    assert check_world("vrc_task_1", 6).configs == (1, 2, 3, 4, 5, 6)
    with pytest.raises(InvalidInput, match="no run configuration 7"):
        check_world("vrc_task_1", 7)
    task = open_task(team_a.id, world="vrc_task_1", run_config=6)
    started = Run(task_id=task.id, team_id=team_a.id, state=RunState.STARTING)
    db.session.add(started)
    db.session.flush()
    command = simulator_command(started, "10.0.0.2", ["10.0.0.0/24"])
    assert f"> {run_dir(started.id)}/world.json && systemd-run" in command
    assert f"--world-file {run_dir(started.id)}/world.json" in command
    assert "22.5,3.0,0.0" in command and "--config 6" in command


def test_admins_update_through_the_documented_api(app: Flask) -> None:
    client = app.test_client()
    admin, officer = token_for(make_user(Role.ADMIN)), token_for(make_user(Role.OFFICER))
    assert client.get("/api/v1/worlds", headers=officer).status_code == 403
    listed = client.get("/api/v1/worlds", headers=admin).get_json()
    first = listed[0]
    assert (first["name"], first["version"], first["configs"]) == (
        "vrc_task_1",
        1,
        [1, 2, 3, 4, 5],
    )
    body = {"document": _moved_gate()}
    assert client.put("/api/v1/worlds/vrc_task_1", json=body, headers=officer).status_code == 403
    answer = client.put("/api/v1/worlds/vrc_task_1", json=body, headers=admin)
    assert answer.status_code == 200, answer.get_json()
    assert answer.get_json()["changed"] and answer.get_json()["world"]["version"] == 2
    shown = client.get("/api/v1/worlds/vrc_task_1", headers=admin).get_json()
    assert shown["document"]["configs"]["2"]["objects"]["gate_1"]["pose"] == [22.5, 3.0, 0.0]
    bad = {"document": _moved_gate() | {"time_limit_s": -1}}
    refused = client.put("/api/v1/worlds/vrc_task_1", json=bad, headers=admin)
    assert refused.status_code == 400
    assert "vrc_task_1.time_limit_s: must be at least" in refused.get_json()["message"]
    other = client.put("/api/v1/worlds/vrc_task_2", json=body, headers=admin)
    assert other.status_code == 400 and "not 'vrc_task_2'" in other.get_json()["message"]
    assert client.get("/api/v1/worlds/nowhere", headers=admin).status_code == 404
    assert _row().version == 2


def test_the_page_form_uploads_a_yaml_file_and_shows_errors(app: Flask) -> None:
    client = app.test_client()
    log_in(client, make_user(Role.ADMIN))
    page = client.get("/worlds").get_data(as_text=True)
    assert 'data-world="vrc_task_3"' in page
    upload = {
        "csrf_token": csrf_token(page),
        "file": (io.BytesIO(yaml.safe_dump(_moved_gate()).encode()), "vrc_task_1.yaml"),
        "text": "",
    }
    answer = client.post("/worlds", data=upload, content_type="multipart/form-data")
    assert answer.status_code == 302 and answer.headers["Location"].endswith("/worlds/vrc_task_1")
    shown = client.get("/worlds/vrc_task_1").get_data(as_text=True)
    assert "vrc_task_1 is now version 2" in shown and "22.5" in shown
    download = client.get("/worlds/vrc_task_1.json")
    assert json.loads(download.data) == _moved_gate()
    pasted = {"csrf_token": csrf_token(page), "text": "name: vrc_task_1\ntitle: [oops"}
    refused = client.post("/worlds", data=pasted)
    assert refused.status_code == 400 and "not JSON or YAML" in refused.get_data(as_text=True)
    user = app.test_client()
    log_in(user, make_user(Role.OFFICER))
    assert user.get("/worlds").status_code in (403, 404)
    assert _row().version == 2


def test_the_command_line_lists_shows_and_updates(
    run: Callable[..., Result],  # noqa: F811 (`cloudsim` on a database `db upgrade` made)
    tmp_path: Path,
) -> None:
    invoke = run
    listed = invoke("world", "list", "--json")
    assert [w["version"] for w in json.loads(listed.output)] == [1, 1, 1]
    shown = json.loads(invoke("world", "show", "vrc_task_1").output)
    shown["configs"]["2"]["objects"]["gate_1"]["pose"] = [22.5, 3.0, 0.0]
    path = tmp_path / "vrc_task_1.json"
    path.write_text(json.dumps(shown))
    updated = invoke("world", "update", str(path), "--json")
    assert updated.exit_code == 0, updated.output
    assert json.loads(updated.output)["version"] == 2
    path.write_text(json.dumps(shown | {"objects": []}))
    refused = invoke("world", "update", str(path))
    assert refused.exit_code != 0 and "invalid world" in refused.output
    assert "version 2" in invoke("world", "list").output
