"""Deploying, assigning and terminating team instances: the rules, the CLI as the README shows
it, the page's assign form; nothing reaches a machine here (no worker runs the launches)."""

from __future__ import annotations

import contextlib
import io
import json
import threading
import uuid
import zipfile
from datetime import UTC, datetime
from pathlib import Path

import pytest
from click.testing import CliRunner
from drcsim.worlds import shipped_document
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.errors import Conflict, Forbidden, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.jobs.runner import run_job
from cloudsim.jobs.service import enqueue
from cloudsim.launched_constellations.keys import instance_tls
from cloudsim.launched_constellations.service import ssh_bundle
from cloudsim.models import (
    ConstellationState,
    InstanceState,
    Job,
    JobState,
    Role,
    Team,
    TeamInstance,
    utcnow,
)
from cloudsim.team_instances import lifecycle, service
from cloudsim.team_instances.client import Endpoint, InstanceError
from cloudsim.team_instances.poll import check_instances
from cloudsim.team_instances.sync import SYNC_JOB, InstanceJob, sync_lock
from cloudsim.worlds.service import update_world
from tests.competition.support import open_task
from tests.conftest import csrf_token, log_in, make_user, token_for
from tests.support.servers import RedisServer, wait_for


def test_rules(app: Flask, team_a: Team, team_b: Team) -> None:
    officer = make_user(Role.OFFICER)
    with pytest.raises(Forbidden):
        service.deploy(officer, name="x", provider="local")
    with pytest.raises(InvalidInput, match="spares"):
        service.deploy(SYSTEM, name="x", provider="local", team_id=team_a.id, count=2)
    with pytest.raises(InvalidInput, match="count"):
        service.deploy(SYSTEM, name="x", provider="local", count=51)
    with pytest.raises(NotFound):
        service.deploy(SYSTEM, name="x", provider="local", team_id=999_999)
    with pytest.raises(InvalidInput, match="provider"):
        service.deploy(SYSTEM, name="x", provider="nowhere")
    ((ours, _),) = service.deploy(SYSTEM, name="team-a", provider="local", team_id=team_a.id)
    assert ours.state == InstanceState.DEPLOYING and ours.constellation.kind == "cloudsim"
    assert ours.constellation.team_id is None  # the master's machinery: no team lists it
    with pytest.raises(Conflict, match="already has"):
        service.deploy(SYSTEM, name="team-a2", provider="local", team_id=team_a.id)
    spares = [i for i, _ in service.deploy(SYSTEM, name="spare", provider="local", count=2)]
    assert [s.name for s in spares] == ["spare-1", "spare-2"]
    with pytest.raises(Conflict, match="already has"):
        service.assign(SYSTEM, "spare-1", team_a.id)
    assert service.assign(SYSTEM, "spare-1", team_b.id).team_id == team_b.id
    with pytest.raises(Conflict, match="already serves"):
        service.assign(SYSTEM, "spare-1", team_a.id)
    service.terminate(SYSTEM, "spare-2")
    with pytest.raises(Conflict, match="terminated"):
        service.terminate(SYSTEM, "spare-2")
    with pytest.raises(Forbidden):
        service.get_instance(officer, ours.id)


def test_assign_form_on_the_page(app: Flask, team_a: Team) -> None:
    admin = make_user(Role.ADMIN)
    ((spare, _),) = service.deploy(SYSTEM, name="spare", provider="local")
    db.session.commit()
    client = app.test_client()
    log_in(client, admin)
    page = client.get(f"/team-instances/{spare.id}").get_data(as_text=True)
    assert "Assign to a team" in page
    answer = client.post(
        f"/team-instances/{spare.id}/assign",
        data={"csrf_token": csrf_token(page), "team": str(team_a.id)},
    )
    assert answer.status_code == 302
    db.session.expire_all()
    assert db.session.get(TeamInstance, spare.id).team_id == team_a.id  # type: ignore[union-attr]


def test_cli_as_the_readme_shows_it(
    tmp_path: Path, redis_server: RedisServer, encryption_key: str
) -> None:
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance"),
        "CLOUDSIM_REDIS_URL": redis_server.url(0),  # a broker, but no worker behind it
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_LOCAL_PREFIX": "ticli",
    }

    def cli(*args: str) -> str:
        result = CliRunner().invoke(main, list(args), env=env)
        assert result.exit_code == 0, result.output
        return result.output

    cli("db", "upgrade")
    cli("team", "create", "Team 8")
    cli("instance", "deploy", "--name", "spare", "--count", "2")
    cli("instance", "assign", "spare-1", "--team", "Team 8")
    listed = json.loads(cli("instance", "list", "--json"))
    assert {(i["name"], i["team"], i["state"]) for i in listed} == {
        ("spare-1", "Team 8", "deploying"),
        ("spare-2", None, "deploying"),
    }
    assert "terminated" in cli("instance", "terminate", "spare-2")
    bad = CliRunner().invoke(main, ["instance", "assign", "spare-9", "--team", "Team 8"], env=env)
    assert bad.exit_code == 1 and bad.output.startswith("Error: team instance spare-9 not found")


def test_a_change_starts_a_sync_job_per_instance_concerned(app: Flask, team_a: Team) -> None:
    ((ours, _),) = service.deploy(SYSTEM, name="team-a", provider="local", team_id=team_a.id)
    ((spare, _),) = service.deploy(SYSTEM, name="spare", provider="local")
    ours.state = spare.state = InstanceState.READY
    db.session.commit()

    seen = {ours.id: 0, spare.id: 0}

    def new_syncs() -> dict[int, int]:
        query = select(Job.target_id).where(Job.kind == "team_instance.sync")
        counts = {key: list(db.session.scalars(query)).count(key) for key in seen}
        new = {key: counts[key] - seen[key] for key in seen}
        seen.update(counts)
        return new

    new_syncs()
    task = open_task(team_a.id)
    assert new_syncs() == {ours.id: 1, spare.id: 0}
    task.name = "Renamed on the master"  # committed without a flush first
    db.session.commit()
    assert new_syncs() == {ours.id: 1, spare.id: 0}
    officer = make_user(Role.OFFICER)  # officers are on every instance
    assert new_syncs() == {ours.id: 1, spare.id: 1}
    member = make_user(Role.USER, team_a)
    assert new_syncs() == {ours.id: 1, spare.id: 0}
    member.last_login_at = officer.last_login_at = utcnow()  # logging in changes no instance
    db.session.commit()
    assert new_syncs() == {ours.id: 0, spare.id: 0}
    admin = make_user(Role.ADMIN)  # admins are not propagated
    assert new_syncs() == {ours.id: 0, spare.id: 0}
    officer.role = Role.ADMIN  # but an officer who becomes one leaves every instance
    db.session.commit()
    assert new_syncs() == {ours.id: 1, spare.id: 1}
    admin.name = "Renamed admin"
    db.session.commit()
    assert new_syncs() == {ours.id: 0, spare.id: 0}
    world = shipped_document("vrc_task_2")
    world["configs"]["2"]["terrain"]["mud"]["friction"] = 0.45
    update_world(admin, world)  # every instance holds every world
    db.session.commit()
    assert new_syncs() == {ours.id: 1, spare.id: 1}


def test_the_ssh_bundle_gives_the_https_address_and_the_ca(app: Flask) -> None:
    ((spare, _),) = service.deploy(SYSTEM, name="spare", provider="local")
    constellation = spare.constellation
    bundle = zipfile.ZipFile(io.BytesIO(ssh_bundle(SYSTEM, constellation.id)[1]))
    assert "(not created yet)" in bundle.read("cloudsim-admin.txt").decode()
    assert "cloudsim-ca.crt" not in bundle.namelist()  # nothing made by a download
    constellation.machines[0].public_ip = "198.18.0.9"
    tls = instance_tls(constellation)  # what the launch job makes at install
    bundle = zipfile.ZipFile(io.BytesIO(ssh_bundle(SYSTEM, constellation.id)[1]))
    assert "https://198.18.0.9:5000/" in bundle.read("cloudsim-admin.txt").decode()
    assert bundle.read("cloudsim-ca.crt").decode() == tls.ca_cert


def test_syncs_of_one_instance_take_turns(app: Flask, team_a: Team) -> None:
    ((instance, _),) = service.deploy(SYSTEM, name="team-a", provider="local", team_id=team_a.id)
    instance.state = InstanceState.READY
    instance.constellation.state = ConstellationState.READY
    db.session.commit()
    config = app.config["CLOUDSIM"]

    def unreachable(_: TeamInstance, __: Config) -> Endpoint:
        raise InstanceError("no route (this test's instance)")

    lock = sync_lock(instance.id)
    assert lock.acquire(blocking=False)
    # The reconcile leaves an instance whose sync is under way alone ...
    check_instances(config, [instance.id], unreachable)
    assert instance.state == InstanceState.READY and instance.error is None
    # ... and a sync job waits for it: it ends only after the lock is released.
    job = enqueue(SYNC_JOB, SYSTEM, InstanceJob(instance.id))
    db.session.commit()

    def run() -> None:
        with app.app_context():
            with contextlib.suppress(Exception):
                run_job(job.id)

    worker = threading.Thread(target=run)
    worker.start()
    wait_for(lambda: _state(job.id) == JobState.RUNNING, 30, "the job to start")
    released = utcnow()
    lock.release()
    worker.join(60)
    db.session.expire_all()
    done = db.session.get(Job, job.id)
    assert done is not None and done.state == JobState.FAILED and done.finished_at is not None
    assert done.finished_at >= released and "no public address" in (done.error or "")
    check_instances(config, [instance.id], unreachable)  # free again: visited
    assert instance.state == InstanceState.UNREACHABLE


def _state(job_id: str) -> JobState | None:
    db.session.expire_all()
    job = db.session.get(Job, job_id)
    return job.state if job is not None else None


def test_the_instance_page_and_api_say_its_step_since_when_and_when_it_was_heard(
    app: Flask, team_a: Team
) -> None:
    ((instance, _),) = service.deploy(SYSTEM, name="team-a", provider="local", team_id=team_a.id)
    lifecycle.healthy(instance, "https://192.0.2.7", {"version": "1.0"})
    heard = instance.heard_at
    assert heard is not None
    lifecycle.unreachable(instance, "no route")  # checked again, not heard from
    assert instance.checked_at is not None and instance.checked_at >= heard
    sync = Job(
        id=str(uuid.uuid4()),
        kind=SYNC_JOB,
        target_type="team_instance",
        target_id=instance.id,
        state=JobState.RUNNING,
        stage="push",
        log="00:10:01 == connect\n00:10:02 == push\n",
    )
    db.session.add(sync)
    db.session.commit()
    sync.updated_at = datetime(2026, 11, 28, 0, 10, 5, tzinfo=UTC)
    db.session.commit()
    assert instance.heard_at == heard

    admin = make_user(Role.ADMIN)
    answer = (
        app.test_client()
        .get(f"/api/v1/team-instances/{instance.id}", headers=token_for(admin))
        .get_json()
    )
    assert (answer["job_kind"], answer["job_state"]) == (SYNC_JOB, "running")
    assert (answer["step"], answer["step_since"]) == ("push", "2026-11-28T00:10:02+00:00")
    assert answer["heard_at"].startswith(heard.strftime("%Y-%m-%dT%H:%M:%S"))
    assert answer["state"] == "unreachable"
    client = app.test_client()
    log_in(client, admin)
    page = client.get(f"/team-instances/{instance.id}").get_data(as_text=True)
    assert heard.strftime("%Y-%m-%d %H:%M:%S UTC") in page.split('id="heard"', 1)[1]
    step = page.split('id="step"', 1)[1].split("</dd>", 1)[0]
    assert "team_instance.sync (running): push" in step and "2026-11-28T00:10:02" in step
    member = make_user(Role.USER, team_a)
    refused = app.test_client().get(
        f"/api/v1/team-instances/{instance.id}", headers=token_for(member)
    )
    assert refused.status_code in (403, 404)
