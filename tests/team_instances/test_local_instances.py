"""A master deploys two team instances on local hosts: real CloudSims (own database, Redis,
worker) on their own public addresses, reached only over HTTPS with a pinned certificate."""

from __future__ import annotations

import base64
import hashlib
import shlex
import subprocess
import time
from collections.abc import Callable
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, cast

import pytest
from click.testing import CliRunner
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from drcsim.worlds import document_digest, shipped_document
from flask import Flask, current_app
from playwright.sync_api import Browser, Page, Playwright, expect, sync_playwright
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.ssh_keys import add_key
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import (
    instance_admin_password,
    instance_admin_token,
    instance_tls,
)
from cloudsim.models import (
    Constellation,
    InstanceState,
    Job,
    JobState,
    Role,
    Run,
    Task,
    Team,
    TeamInstance,
    User,
    utcnow,
)
from cloudsim.people.service import create_team, update_user
from cloudsim.portal.credentials import upload_token
from cloudsim.providers.service import open_provider
from cloudsim.team_instances.client import CallRefused, call
from cloudsim.team_instances.poll import CATCH_UP_EVERY, catch_up, check_instances, endpoint_of
from cloudsim.team_instances.restore import run_on_instance, with_settings
from cloudsim.worlds.service import update_world
from tests.competition.support import open_task
from tests.conftest import PASSWORD, csrf_token, log_in, make_user, token_for
from tests.launched_constellations.conftest import finished, leftovers
from tests.portal.test_forged_runs import honest_record
from tests.support.servers import wait_for
from tests.team_instances.test_sync import KEY
from tests.web.test_browser import CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.hosts


def ready(config: Config) -> list[TeamInstance] | None:
    """Check the instances once; return them when every one is ready with a live worker."""
    db.session.expire_all()
    instances = check_instances(config)
    db.session.commit()
    done = all(i.state == InstanceState.READY and i.health.get("worker") for i in instances)
    return instances if done else None


# two real CloudSims deployed, then propagation, seizure, restore and catch-up: ~10 min on a
# loaded 2-core machine, over the suite's default 600 s
@pytest.mark.timeout(1500)
def test_master_deploys_team_instances_and_pins_their_certificates(
    constellations_app: Flask,
    constellations_worker: None,
    constellations_config: Config,
    tmp_path: Path,
) -> None:
    team_a, team_b = create_team(SYSTEM, "Team A"), create_team(SYSTEM, "Team B")
    admin = make_user(Role.ADMIN)
    client = constellations_app.test_client()
    # As the README says: the API with its documented body ...
    answer = client.post(
        "/api/v1/team-instances",
        json={"name": "team-a", "provider": "local", "team_id": team_a.id},
        headers=token_for(admin),
    )
    assert answer.status_code == 202, answer.get_json()
    jobs = [answer.get_json()[0]["job"]["id"]]
    # ... and the page's form, really submitted.
    log_in(client, admin)
    page = client.get("/team-instances").get_data(as_text=True)
    form = {
        "csrf_token": csrf_token(page),
        "name": "team-b",
        "provider": "local",
        "team": str(team_b.id),
        "count": "1",
    }
    answer = client.post("/team-instances", data=form)
    assert answer.status_code == 302, answer.get_data(as_text=True)
    second = db.session.scalar(select(TeamInstance).where(TeamInstance.name == "team-b"))
    assert second is not None and second.team_id == team_b.id
    jobs.append(
        db.session.scalar(
            select(Job.id).where(
                Job.target_type == "constellation", Job.target_id == second.constellation_id
            )
        )
    )
    for job_id in jobs:
        done = finished(job_id, 900)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
        constellation = db.session.get(Constellation, done.target_id)
        assert constellation is not None
        # the instance's admin password and the master's token on it never reach the job log
        for secret in (instance_admin_password(constellation), instance_admin_token(constellation)):
            assert secret not in done.log

    instances = cast(
        list[TeamInstance], wait_for(lambda: ready(constellations_config), 120, "instances ready")
    )
    for instance in instances:
        address = instance.constellation.machines[0].public_ip
        assert instance.url == f"https://{address}:5000/"
        assert instance.version and instance.health["database"] and instance.health["queue"]
        assert instance.team_id in {team_a.id, team_b.id}
    page = client.get("/team-instances").get_data(as_text=True)
    assert page.count('class="state ready">ready') == 2 and "worker up" in page

    # No plain HTTP on the public address: the port speaks TLS only.
    driver = open_provider("local", constellations_config).driver
    first = instances[0]
    plain = _raw_exchange(
        driver.ex_public_proxy_command(first.constellation.machines[0].public_ip, 5000) or [],
        b"GET /login HTTP/1.0\r\nHost: team\r\n\r\n",
    )
    assert not plain.startswith(b"HTTP/")

    # A certificate that is not the pinned one is refused: the instance is unreachable, why shown.
    pinned = first.cert_fingerprint
    first.cert_fingerprint = "00" * 32
    db.session.commit()
    check_instances(constellations_config, [first.id])
    assert first.state == InstanceState.UNREACHABLE
    assert "does not match the pinned" in (first.error or "")
    assert "does not match the pinned" in client.get(f"/team-instances/{first.id}").get_data(
        as_text=True
    )
    first.cert_fingerprint = pinned
    check_instances(constellations_config, [first.id])
    assert first.state == InstanceState.READY, first.error
    db.session.commit()

    _propagation(constellations_config, instances, team_a, team_b, tmp_path)

    for instance in instances:
        response = client.delete(f"/api/v1/team-instances/{instance.id}", headers=token_for(admin))
        assert response.status_code == 202
        assert finished(response.get_json()["id"]).state == JobState.SUCCEEDED
    assert leftovers(constellations_config) == {"netns": [], "mounts": [], "files": []}
    assert {t.state for t in db.session.scalars(select(TeamInstance))} == {InstanceState.TERMINATED}
    assert db.session.get(Team, team_a.id) is not None


def _raw_exchange(connect: list[str], request: bytes) -> bytes:
    """Send bytes over a connecting command; return what comes back before it closes."""
    with subprocess.Popen(connect, stdin=subprocess.PIPE, stdout=subprocess.PIPE) as peer:
        out, _ = peer.communicate(request, timeout=30)
    return out


def on_instance(instance: TeamInstance, config: Config, path: str, **kwargs: Any) -> Any:
    """Call an instance's API as the master does (pinned HTTPS, the master's admin token)."""
    return call(endpoint_of(instance, config), kwargs.pop("method", "GET"), path, **kwargs)


def _until(condition: Callable[[], bool], what: str) -> None:
    """Wait for the sync jobs to bring an instance to a condition; say what they did if not."""
    try:
        wait_for(condition, 60, what)
    except TimeoutError:
        db.session.expire_all()
        jobs = db.session.scalars(select(Job).where(Job.kind == "team_instance.sync"))
        done = "\n".join(f"{j.state} {j.error} {j.log[-500:]}" for j in jobs)
        rows = [(i.name, i.state, i.sync_error) for i in db.session.scalars(select(TeamInstance))]
        raise AssertionError(f"{what}: sync jobs:\n{done}\ninstances: {rows}") from None


def _world(config: Config, instance: TeamInstance) -> dict[str, Any]:
    found: dict[str, Any] = on_instance(instance, config, "/worlds/vrc_task_1")
    return found


def _behind(instance: TeamInstance) -> bool:
    db.session.refresh(instance)
    return "does not match the pinned" in (instance.sync_error or "")


def _synced(config: Config, instance: TeamInstance, emails: set[str], task: str) -> bool:
    users = {u["email"] for u in on_instance(instance, config, "/users?page_size=500")}
    tasks = {t["name"] for t in on_instance(instance, config, "/tasks?page_size=500")}
    return emails <= users and task in tasks


def _propagation(
    config: Config, instances: list[TeamInstance], team_a: Team, team_b: Team, tmp: Path
) -> None:
    """Users, keys and tasks made on the master reach each team's instance, and only theirs."""
    by_team = {i.team_id: i for i in instances}
    on_a, on_b = by_team[team_a.id], by_team[team_b.id]
    member_a, member_b = make_user(Role.USER, team_a), make_user(Role.USER, team_b)
    officer = make_user(Role.OFFICER)
    add_key(member_a, KEY, "laptop")
    task_a = open_task(team_a.id, name="Walking for A")
    open_task(team_b.id, name="Driving for B")
    # each commit above started a sync job per instance concerned (no poll in between)
    wanted_a = {member_a.email, officer.email}
    _until(lambda: _synced(config, on_a, wanted_a, "Walking for A"), "A in sync")
    _until(lambda: _synced(config, on_b, {member_b.email, officer.email}, "Driving for B"), "B")
    assert member_b.email not in {u["email"] for u in on_instance(on_a, config, "/users")}

    # A task edited on the master reaches the instance.
    task_a.name = "Walking for A, edited"
    db.session.commit()
    _until(lambda: _synced(config, on_a, wanted_a, "Walking for A, edited"), "the edit")

    # A world updated on the master (a gate moved) reaches every instance, whose runs hand
    # that document to their simulator.
    world = shipped_document("vrc_task_1")
    world["configs"]["2"]["objects"]["gate_1"]["pose"] = [22.5, 3.0, 0.0]
    version = update_world(SYSTEM, world).world.version
    db.session.commit()
    for on in (on_a, on_b):
        _until(lambda on=on: _world(config, on)["version"] == version, f"the world on {on.name}")
    moved = _world(config, on_b)["document"]["configs"]["2"]["objects"]["gate_1"]
    assert moved["pose"] == [22.5, 3.0, 0.0]

    # Drift: someone promotes the member on the instance by hand; the reconcile puts it back.
    theirs = next(u for u in on_instance(on_a, config, "/users") if u["email"] == member_a.email)
    on_instance(on_a, config, f"/users/{theirs['id']}", method="PATCH", body={"role": "officer"})
    shipped = {"document": shipped_document("vrc_task_1")}  # and puts a world back
    on_instance(on_a, config, "/worlds/vrc_task_1", method="PUT", body=shipped)
    check_instances(config, [on_a.id])
    db.session.commit()
    assert any(member_a.email in c for c in on_a.sync_report["changed"]), on_a.sync_report
    assert f"world vrc_task_1: version {version}" in on_a.sync_report["changed"]
    assert _world(config, on_a)["digest"] == document_digest(world)
    assert on_instance(on_a, config, f"/users/{theirs['id']}")["role"] == "user"
    assert on_a.last_sync_at is not None and on_a.sync_error is None
    _seized(config, on_a, member_a, theirs["id"])
    _forged_run_refused(on_a, task_a)

    # A cut between the master and A (here: A's certificate no longer matches the pin): the
    # sync jobs for A fail and A's page says why it is behind; B still gets every change;
    # once A answers again, the reconcile catches it up.
    leaving = make_user(Role.USER, team_a)
    in_a = wanted_a | {leaving.email}
    _until(lambda: _synced(config, on_a, in_a, "Walking for A, edited"), "a new member on A")
    assert _active_on(config, on_a, leaving.email)
    pinned, on_a.cert_fingerprint = on_a.cert_fingerprint, "00" * 32
    db.session.commit()
    late = make_user(Role.OFFICER)  # every instance's
    update_user(SYSTEM, leaving.id, active=False)  # disabled while A cannot hear of it
    db.session.commit()
    wanted_b = {member_b.email, officer.email, late.email}
    _until(lambda: _synced(config, on_b, wanted_b, "Driving for B"), "B while A is cut off")
    _until(lambda: _behind(on_a), "A's page saying why it is behind")
    on_a.cert_fingerprint = pinned
    db.session.commit()
    # A answers again: the catch-up (beat, every second; ticked here as the beat would) brings
    # it up to date within about 2 s, not at the next poll.
    beat = _Beat(config)
    wait_for(
        lambda: beat.tick() and not _active_on(config, on_a, leaving.email),
        CATCH_UP_DEADLINE,
        "the member disabled on the master disabled on A, once A answers again",
    )
    db.session.refresh(on_a)
    assert on_a.sync_error is None and _synced(
        config, on_a, wanted_a | {late.email}, "Walking for A, edited"
    )

    # The member logs in to their instance in Chromium, with the master's password; sees
    # their team's task only; is locked out once disabled on the master.
    with sync_playwright() as playwright:
        browser = instance_browser(playwright, config, on_a, tmp)
        page = browser.new_page()
        base = log_in_instance(page, on_a, member_a)
        page.goto(f"{base}/tasks")
        expect(page.get_by_text("Walking for A, edited")).to_be_visible()
        assert "Driving for B" not in page.content() and "Team B" not in page.content()
        update_user(SYSTEM, member_a.id, active=False)
        db.session.commit()  # pushed at once by the sync job
        wait_for(
            lambda: (
                not next(
                    u for u in on_instance(on_a, config, "/users") if u["email"] == member_a.email
                )["active"]
            ),
            60,
            "the member disabled on the instance",
        )
        page.goto(f"{base}/tasks")
        expect(page.get_by_label("Password")).to_be_visible()  # sent back to the login form
        browser.close()


CATCH_UP_DEADLINE = 2.5  # the 2 s promised, and a tick's own time


class _Beat:
    """Send the catch-up as the beat does: at most once a second."""

    def __init__(self, config: Config) -> None:
        self.config, self.last = config, 0.0

    def tick(self) -> bool:
        if time.monotonic() - self.last >= CATCH_UP_EVERY.total_seconds():
            self.last = time.monotonic()
            db.session.expire_all()
            catch_up(self.config)
            db.session.commit()
        return True


def _active_on(config: Config, instance: TeamInstance, email: str) -> bool:
    users = on_instance(instance, config, "/users?page_size=500")
    return bool(next(u for u in users if u["email"] == email)["active"])


def _forged_run_refused(instance: TeamInstance, task: Task) -> None:
    """The report's forged result, sent with the upload token the master handed the deployed
    instance: score 9 on a world of 4 checkpoints is refused with the reason, nothing stored."""
    task.window_start = utcnow() - timedelta(hours=1)  # open long before the run below
    db.session.commit()
    record = honest_record({"id": task.id, "name": task.name})
    # its run (75 s of wall clock) ended a second ago, inside the task's window
    late = utcnow() - datetime.fromisoformat(record["finished_at"]) - timedelta(seconds=1)
    for event in record["score_events"]:
        event["wall_time"] = (datetime.fromisoformat(event["wall_time"]) + late).isoformat()
    for field in ("started_at", "finished_at"):
        record[field] = (datetime.fromisoformat(record[field]) + late).isoformat()
    record.update(
        team=task.team.name,
        world=task.world,
        run_config=task.run_config,
        timeout_s=task.timeout_s,
        uplink_bits=task.uplink_bits,
        downlink_bits=task.downlink_bits,
        score=9,
    )
    headers = {"Authorization": f"Bearer {upload_token(instance)}"}
    sent = current_app.test_client().put(
        "/api/v1/portal/ingest/runs/1", json=record, headers=headers
    )
    assert sent.status_code == 400, sent.json
    assert "score 9 on a world of 4 checkpoints" in sent.json["message"]
    assert db.session.scalar(select(Run).where(Run.instance_id == instance.id)) is None


def _seized(config: Config, on_a: TeamInstance, member: User, member_id: int) -> None:
    """The report's seizure of an instance, and what stops it: a member made an admin by hand
    (the documented call) and an admin account made there are put back by the reconcile, the
    master's page, API and audit log show the drift; the master's own account cannot be
    disabled there, and `cloudsim instance restore-access` gives it back when it was lost."""
    on_instance(on_a, config, f"/users/{member_id}", method="PATCH", body={"role": "admin"})
    made = {"email": "made-here@example.org", "role": "admin", "password": "x" * 16}
    local = on_instance(on_a, config, "/users", method="POST", body=made)
    check_instances(config, [on_a.id])
    db.session.commit()
    drift = on_a.sync_report["drift"]
    assert f"user {member.email}: role, team_id" in drift, on_a.sync_report
    assert "user made-here@example.org (admin) disabled: made here" in drift
    assert on_instance(on_a, config, f"/users/{member_id}")["role"] == "user"
    assert not on_instance(on_a, config, f"/users/{local['id']}")["active"]
    admin = token_for(make_user(Role.ADMIN))
    client = current_app.test_client()
    shown = client.get(f"/api/v1/team-instances/{on_a.id}", headers=admin).get_json()
    assert shown["sync_report"]["drift"] == drift
    audit = client.get("/api/v1/audit?action=team_instance.drift", headers=admin).get_json()
    assert audit[0]["target_id"] == str(on_a.id) and audit[0]["details"]["put_back"] == drift

    # The master's own account on the instance cannot be disabled there ...
    me = on_instance(on_a, config, "/me")
    with pytest.raises(CallRefused) as refused:
        on_instance(on_a, config, f"/users/{me['id']}", method="PATCH", body={"active": False})
    assert refused.value.code == 409 and "master manages" in str(refused.value)
    # ... but it can be lost anyway (here: every token revoked in the instance's database by
    # root on its machine); the documented command on the master gives it back.
    run_on_instance(on_a, config, with_settings(["python", "-c", REVOKE_EVERY_TOKEN]))
    with pytest.raises(CallRefused) as refused:
        on_instance(on_a, config, "/me")
    assert refused.value.code == 401
    result = CliRunner().invoke(main, ["instance", "restore-access", on_a.name], env=_env(config))
    assert result.exit_code == 0, result.output
    assert f"{on_a.name}: the master's token un-revoked" in result.output
    assert f"{on_a.name}: answers the master again" in result.output
    assert on_instance(on_a, config, "/me")["id"] == me["id"]


REVOKE_EVERY_TOKEN = """
from sqlalchemy import update
from cloudsim.app import create_app
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import ApiToken, utcnow
with create_app(Config.from_env()).app_context():
    db.session.execute(update(ApiToken).values(revoked_at=utcnow()))
    db.session.commit()
"""


def _env(config: Config) -> dict[str, str]:
    """Return the settings of the test's master as `cloudsim` commands read them."""
    return {
        "CLOUDSIM_INSTANCE_DIR": str(config.instance_dir),
        "CLOUDSIM_DATABASE_URL": config.database_url,
        "CLOUDSIM_REDIS_URL": config.effective_redis_url,
        "CLOUDSIM_ENCRYPTION_KEYS": ",".join(config.encryption_keys),
        "CLOUDSIM_SECRET_KEY": config.secret_key,
        "CLOUDSIM_LOCAL_PREFIX": config.local_prefix,
        "CLOUDSIM_LOCAL_SUBNET_POOL": config.local_subnet_pool,
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": config.local_public_cidr,
    }


def instance_browser(
    playwright: Playwright, config: Config, instance: TeamInstance, tmp: Path
) -> Browser:
    """Start Chromium on "the internet" side of the local provider, trusting the instance's
    certificate (its public key pinned, as the master pins the certificate)."""
    driver = open_provider("local", config).driver
    chromium = tmp / "chromium-on-the-internet"
    chromium.write_text(
        "#!/bin/sh\nexec " + shlex.join(driver.ex_public_command([CHROMIUM]) or []) + ' "$@"\n'
    )
    chromium.chmod(0o755)
    spki = _spki_pin(instance_tls(instance.constellation).cert)
    return playwright.chromium.launch(
        executable_path=str(chromium),
        args=[*CHROMIUM_ARGS, f"--ignore-certificate-errors-spki-list={spki}"],
    )


def log_in_instance(page: Page, instance: TeamInstance, user: User) -> str:
    """Log a user in to an instance's pages with the master's password; return its base URL."""
    base = (instance.url or "").rstrip("/")
    page.goto(f"{base}/login")
    page.get_by_label("E-mail").fill(user.email)
    page.get_by_label("Password").fill(PASSWORD)
    page.get_by_role("button", name="Log in").click()
    return base


def _spki_pin(cert_pem: str) -> str:
    """Return Chromium's pin of a certificate's public key (base64 SHA-256 of its SPKI)."""
    cert = x509.load_pem_x509_certificate(cert_pem.encode())
    spki = cert.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )
    return base64.b64encode(hashlib.sha256(spki).digest()).decode()
