"""The portal's upload API as a stranger uses it: the bodies the README and the OpenAPI
document describe, written by hand, a log sent in two pieces with a look at the offset."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterator
from datetime import timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask import Flask

from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Role, TeamInstance, utcnow
from cloudsim.portal.credentials import upload_token
from provisioners.remote import pki
from tests.conftest import make_user, running_app, token_for
from tests.portal.support import team_instance
from tests.support.servers import PostgresServer, RedisServer


@pytest.fixture
def master(make_config: Callable[..., Config], postgres_server: PostgresServer) -> Iterator[Flask]:
    # PostgreSQL, as a master runs: it refuses ids SQLite would take (past int32)
    database = postgres_server.create_database("cloudsim_portal_api")
    with running_app(make_config(database, portal_url="https://127.0.0.1:5443/")) as app:
        yield app


def test_a_run_and_its_log_uploaded_as_documented(master: Flask) -> None:
    client = master.test_client()
    admin, officer = token_for(make_user(Role.ADMIN)), token_for(make_user(Role.OFFICER))
    team = client.post("/api/v1/teams", json={"name": "Team A"}, headers=officer).json
    now = utcnow()
    task = client.post(
        "/api/v1/tasks",
        json={
            "name": "Walking 1",
            "world": "vrc_task_2",
            "run_config": 1,
            "start": (now - timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
            "stop": (now + timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
            "time_zone": "UTC",
            "uplink_bits": 115_200,
            "downlink_bits": 59_000_000,
            "team_ids": [team["id"]],
        },
        headers=officer,
    ).json[0]
    deployed = client.post(
        "/api/v1/team-instances",
        json={"name": "ti-a", "provider": "local", "team_id": team["id"]},
        headers=admin,
    )
    assert deployed.status_code == 202, deployed.json
    instance = db.session.get(TeamInstance, deployed.json[0]["instance"]["id"])
    assert instance is not None
    # what the desired state hands the instance as "portal": {"token": ...}
    uploader = {"Authorization": f"Bearer {upload_token(instance)}"}
    db.session.commit()
    log = b'{"t": 1.0, "checkpoint": 1}\n' * 5000
    started = now - timedelta(minutes=30)
    record = {
        "team": "Team A",
        "task_key": f"m{task['id']}",
        "task_name": "Walking 1",
        "world": "vrc_task_2",
        "run_config": 1,
        "state": "finished",
        "end_reason": "time_limit",
        "score": 1,
        "falls": 0,
        "sim_seconds": 1800.0,
        "uplink_bits_used": 100_000,
        "downlink_bits_used": 1_000_000,
        "uplink_bits": 115_200,
        "downlink_bits": 59_000_000,
        "timeout_s": task["timeout_s"],
        "seconds_left": 0.0,
        "started_at": started.isoformat(),
        "finished_at": (started + timedelta(minutes=31)).isoformat(),
        "score_events": [
            {
                "kind": "checkpoint",
                "checkpoint": 1,
                "points": 1,
                "sim_time": 412.5,
                "wall_time": (started + timedelta(seconds=413)).isoformat(),
            },
            {  # every run a simulator ends has this last one
                "kind": "run_end",
                "points": 0,
                "sim_time": 1800.0,
                "wall_time": (started + timedelta(minutes=30)).isoformat(),
                "description": "time_limit",
            },
        ],
        "logs": [
            {
                "filename": "score.jsonl",
                "kind": "score",
                "size": len(log),
                "sha256": hashlib.sha256(log).hexdigest(),
            },
            {  # an empty log (no commands sent): no piece to send, stored as it is declared
                "filename": "commands.jsonl",
                "kind": "commands",
                "size": 0,
                "sha256": hashlib.sha256(b"").hexdigest(),
            },
            *(  # what a finished run is re-simulated from is declared too (empty here)
                {
                    "filename": name,
                    "kind": kind,
                    "size": 0,
                    "sha256": hashlib.sha256(b"").hexdigest(),
                }
                for name, kind in (("meta.json", "meta"), ("state.msgpack", "state"))
            ),
        ],
    }
    base = "/api/v1/portal/ingest/runs/7"
    sent = client.put(base, json=record, headers=uploader)
    assert sent.status_code == 200, sent.json
    assert sent.json["logs"][0]["received"] == 0 and not sent.json["complete"]
    assert sent.json["logs"][1]["complete"]
    half = len(log) // 2
    piece = client.put(
        f"{base}/logs/score.jsonl?offset=0",
        data=log[:half],
        headers=uploader,
        content_type="application/octet-stream",
    )
    assert piece.status_code == 200 and piece.json["received"] == half, piece.json
    assert client.post(f"{base}/complete", headers=uploader).status_code == 409  # not all yet
    where = client.get(f"{base}/logs/score.jsonl", headers=uploader).json["received"]
    rest = client.put(
        f"{base}/logs/score.jsonl?offset={where}",
        data=log[where:],
        headers=uploader,
        content_type="application/octet-stream",
    )
    assert rest.status_code == 200 and rest.json["complete"], rest.json
    done = client.post(f"{base}/complete", headers=uploader)
    assert done.status_code == 200 and done.json["complete"]
    run = client.get(f"/api/v1/runs/{done.json['run_id']}", headers=officer).json
    assert (run["instance_id"], run["remote_run_id"], run["score"]) == (instance.id, 7, 1)
    assert run["score_events"][0]["sim_time"] == 412.5
    logs = {a["filename"]: a["id"] for a in run["artifacts"]}
    stored = client.get(f"/api/v1/runs/{run['id']}/logs/{logs['score.jsonl']}", headers=officer)
    assert stored.data == log
    assert stored.headers["X-Checksum-SHA256"] == hashlib.sha256(log).hexdigest()
    # the same body again: the same run; other caps than the task's: refused
    assert client.put(base, json=record, headers=uploader).json["run_id"] == run["id"]
    other = client.put(
        "/api/v1/portal/ingest/runs/8", json=dict(record, uplink_bits=1), headers=uploader
    )
    assert other.status_code == 403 and "caps" in other.json["message"]
    unknown = client.put(
        "/api/v1/portal/ingest/runs/8", json=dict(record, task_key="m99999999999"), headers=uploader
    )
    assert unknown.status_code == 403 and "not scheduled" in unknown.json["message"]
    for field in ("running_at", "uplink_spent_at"):  # a time UTC cannot hold: 400, not a 500
        early = dict(record, state="error", **{field: "0001-01-01T00:00:00+05:00"})
        answer = client.put("/api/v1/portal/ingest/runs/9", json=early, headers=uploader)
        assert answer.status_code == 400 and field in answer.json["errors"]["json"], answer.json
    # a user's API token is no upload token, and an upload token opens nothing else
    assert client.put(base, json=record, headers=officer).status_code == 401
    for url in ("/api/v1/runs", f"/api/v1/runs/{run['id']}", "/api/v1/portal/refusals"):
        assert client.get(url, headers=uploader).status_code == 401, url
    # another team's instance does not learn that this upload exists, nor add to it
    team_b = client.post("/api/v1/teams", json={"name": "Team B"}, headers=officer).json
    stranger = {"Authorization": f"Bearer {upload_token(team_instance(team_b['id'], 'ti-b', ''))}"}
    assert client.get(base, headers=stranger).status_code == 404
    assert client.get(f"{base}/logs/score.jsonl", headers=stranger).status_code == 404
    assert client.post(f"{base}/complete", headers=stranger).status_code == 404


def test_cli_as_the_readme_shows_it(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str
) -> None:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
    }
    assert CliRunner().invoke(main, ["db", "upgrade"], env=env).exit_code == 0
    out = tmp_path / "portal"
    unset = CliRunner().invoke(main, ["portal", "certificate", "--out", str(out)], env=env)
    assert unset.exit_code == 1 and "CLOUDSIM_PORTAL_URL" in unset.output
    env["CLOUDSIM_PORTAL_URL"] = "https://198.18.0.1:5443"
    made = CliRunner().invoke(main, ["portal", "certificate", "--out", str(out), "--json"], env=env)
    assert made.exit_code == 0, made.output
    shown = json.loads(made.output)
    cert = Path(shown["cert"]).read_text()
    assert shown["host"] == "198.18.0.1" and shown["sha256"] == pki.certificate_fingerprint(cert)
    assert Path(shown["key"]).stat().st_mode & 0o777 == 0o600
    listed = CliRunner().invoke(main, ["portal", "refusals", "--json"], env=env)
    assert listed.exit_code == 0 and json.loads(listed.output) == []
    env["CLOUDSIM_PORTAL_URL"] = "http://198.18.0.1:5443/"
    bad = CliRunner().invoke(main, ["portal", "refusals"], env=env)
    assert bad.exit_code != 0 and "https://HOST:PORT/" in bad.output
