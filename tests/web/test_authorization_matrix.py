"""Every route, visited as every kind of person, answers exactly as the rules say.

A new route without an entry here fails the test: decide who may use it, then add it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from drcsim.worlds import shipped_document
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.auth.ssh_keys import generate_key
from cloudsim.auth.tokens import issue_token
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Phase,
    Role,
    Team,
    User,
    Webhook,
    utcnow,
)
from cloudsim.seasons.service import PhaseSpec, save_phase
from cloudsim.team_instances import service as team_instances
from tests.competition.support import finished_run, open_task, ready_constellation
from tests.conftest import log_in, make_user, token_for
from tests.team_instances.test_launch import inventory

PERSONAS = ("anon", "user_a", "user_b", "officer", "admin")
_seq = itertools.count(1)

# (endpoint, method) -> expected status per persona, in PERSONAS order.
LOGIN = 302  # a web page sends anonymous visitors to the login form
MATRIX: dict[tuple[str, str], tuple[int, ...]] = {
    # web: auth
    ("auth.login", "GET"): (200, 302, 302, 302, 302),
    ("auth.login", "POST"): (400, 302, 302, 302, 302),
    ("auth.logout", "POST"): (LOGIN, 302, 302, 302, 302),
    ("auth.account", "GET"): (LOGIN, 200, 200, 200, 200),
    ("auth.change_password", "POST"): (LOGIN, 400, 400, 400, 400),
    ("auth.create_token", "POST"): (LOGIN, 400, 400, 400, 400),
    ("auth.revoke", "POST"): (LOGIN, 302, 404, 404, 404),  # only user_a's own token
    ("auth.add_ssh_key", "POST"): (LOGIN, 400, 400, 400, 400),  # an empty key
    ("auth.delete_ssh_key", "POST"): (LOGIN, 302, 404, 404, 404),  # only user_a's own key
    # web: dashboard, people
    ("dashboard.index", "GET"): (LOGIN, 200, 200, 200, 200),
    ("people.teams", "GET"): (LOGIN, 403, 403, 200, 200),
    ("people.create_team", "POST"): (LOGIN, 403, 403, 400, 400),
    ("people.team", "GET"): (LOGIN, 200, 404, 200, 200),  # team A's page
    ("people.rename_team", "POST"): (LOGIN, 403, 403, 400, 400),
    ("people.delete_team", "POST"): (LOGIN, 403, 403, 409, 409),  # team A has members
    ("people.users", "GET"): (LOGIN, 403, 403, 200, 200),
    ("people.create_user", "GET"): (LOGIN, 403, 403, 200, 200),
    ("people.create_user", "POST"): (LOGIN, 403, 403, 400, 400),
    ("people.edit_user", "GET"): (LOGIN, 403, 403, 200, 200),
    ("people.edit_user", "POST"): (LOGIN, 403, 403, 400, 400),
    ("people.delete_user", "POST"): (LOGIN, 403, 403, 302, 302),
    # web: constellations (team A's)
    ("constellations.index", "GET"): (LOGIN, 200, 200, 200, 200),
    ("constellations.launch", "POST"): (LOGIN, 403, 403, 403, 400),
    ("constellations.show", "GET"): (LOGIN, 200, 404, 200, 200),
    ("constellations.status", "GET"): (LOGIN, 200, 404, 200, 200),
    ("constellations.terminate", "POST"): (LOGIN, 403, 403, 403, 302),
    ("constellations.retry", "POST"): (LOGIN, 403, 403, 403, 409),  # it is not in error
    ("constellations.ssh_bundle", "GET"): (LOGIN, 403, 403, 200, 200),
    ("constellations.team_sudo", "POST"): (LOGIN, 403, 403, 302, 302),
    # a team user's own VPN bundle: the fixture's constellation has no router address yet (409);
    # officers and admins are no team members (400) but may ask for a member's
    # (see tests/launched_constellations)
    ("constellations.vpn_bundle", "GET"): (LOGIN, 409, 404, 400, 400),
    # web: jobs, audit
    ("jobs.index", "GET"): (LOGIN, 403, 403, 200, 200),
    ("jobs.start_diagnostics", "POST"): (LOGIN, 403, 403, 403, 302),
    ("jobs.show", "GET"): (LOGIN, 403, 403, 200, 200),
    ("jobs.progress", "GET"): (LOGIN, 403, 403, 200, 200),
    ("audit.index", "GET"): (LOGIN, 403, 403, 200, 200),
    # API
    ("api-docs.openapi_json", "GET"): (200, 200, 200, 200, 200),
    ("api_account.Me", "GET"): (401, 200, 200, 200, 200),
    ("api_account.Tokens", "GET"): (401, 200, 200, 200, 200),
    ("api_account.Tokens", "POST"): (401, 201, 201, 201, 201),
    ("api_account.TokenById", "DELETE"): (401, 204, 404, 404, 404),
    ("api_account.SshKeys", "GET"): (401, 200, 200, 200, 200),
    ("api_account.SshKeys", "POST"): (401, 201, 201, 201, 201),
    ("api_account.SshKeyById", "DELETE"): (401, 204, 404, 404, 404),
    ("api_people.Teams", "GET"): (401, 200, 200, 200, 200),
    ("api_people.Teams", "POST"): (401, 403, 403, 201, 201),
    ("api_people.TeamById", "GET"): (401, 200, 404, 200, 200),
    ("api_people.TeamById", "PATCH"): (401, 403, 403, 200, 200),
    ("api_people.TeamById", "DELETE"): (401, 403, 403, 409, 409),
    ("api_people.Users", "GET"): (401, 403, 403, 200, 200),
    ("api_people.Users", "POST"): (401, 403, 403, 201, 201),
    ("api_people.UserById", "GET"): (401, 404, 404, 200, 200),
    ("api_people.UserById", "PATCH"): (401, 404, 404, 200, 200),
    ("api_people.UserById", "DELETE"): (401, 404, 404, 204, 204),
    ("api_jobs.Jobs", "GET"): (401, 403, 403, 200, 200),
    ("api_jobs.Jobs", "POST"): (401, 403, 403, 403, 202),
    ("api_jobs.JobById", "GET"): (401, 403, 403, 200, 200),
    ("api_audit.Audit", "GET"): (401, 403, 403, 200, 200),
    ("api_constellations.Constellations", "GET"): (401, 200, 200, 200, 200),
    ("api_constellations.Constellations", "POST"): (401, 403, 403, 403, 202),
    ("api_constellations.Capacity", "GET"): (401, 403, 403, 200, 200),
    ("api_constellations.ConstellationById", "GET"): (401, 200, 404, 200, 200),
    ("api_constellations.ConstellationById", "PATCH"): (401, 403, 403, 200, 200),
    ("api_constellations.ConstellationById", "DELETE"): (401, 403, 403, 403, 202),
    ("api_constellations.Retry", "POST"): (401, 403, 403, 403, 409),
    ("api_constellations.SshBundle", "GET"): (401, 403, 403, 200, 200),
    ("api_constellations.VpnBundle", "GET"): (401, 409, 404, 400, 400),
    # competition (team A's open task, finished run and its stored log)
    ("competition.tasks", "GET"): (LOGIN, 200, 200, 200, 200),
    ("competition.schedule_task", "POST"): (LOGIN, 403, 403, 400, 400),
    ("competition.delete_task", "POST"): (LOGIN, 403, 403, 302, 302),
    ("competition.import_schedule", "POST"): (LOGIN, 403, 403, 400, 400),
    ("competition.export_schedule", "GET"): (LOGIN, 403, 403, 200, 200),
    ("competition.start", "POST"): (LOGIN, 302, 403, 302, 302),
    ("competition.runs", "GET"): (LOGIN, 200, 200, 200, 200),
    ("competition.run", "GET"): (LOGIN, 200, 404, 200, 200),
    ("competition.run_status", "GET"): (LOGIN, 200, 404, 200, 200),
    ("competition.stop", "POST"): (LOGIN, 409, 404, 409, 409),  # it has finished
    ("competition.settle", "POST"): (LOGIN, 403, 403, 400, 400),  # the form is empty
    ("competition.download", "GET"): (LOGIN, 200, 404, 200, 200),
    # the season's phases (a fresh phase, open now, scores hidden): everyone reads the rules
    ("seasons.phases", "GET"): (LOGIN, 200, 200, 200, 200),
    ("seasons.schedule_phase", "POST"): (LOGIN, 403, 403, 302, 302),
    ("seasons.reveal", "POST"): (LOGIN, 403, 403, 302, 302),
    ("api_seasons.Phases", "GET"): (401, 200, 200, 200, 200),
    ("api_seasons.PhaseById", "GET"): (401, 200, 200, 200, 200),
    ("api_seasons.SchedulePhase", "POST"): (401, 403, 403, 201, 201),
    ("api_seasons.RevealPhase", "POST"): (401, 403, 403, 200, 200),
    # the portal (team A's page; its finished run has no bandwidth log: 404 for all)
    ("portal.index", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.team", "GET"): (LOGIN, 200, 404, 200, 200),
    ("portal.leaderboard", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.standings", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.figure_page", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.bits_banked_csv", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.uplink_score_csv", "GET"): (LOGIN, 200, 200, 200, 200),
    ("portal.bandwidth_csv", "GET"): (LOGIN, 404, 404, 404, 404),
    ("portal.results_csv", "GET"): (LOGIN, 403, 403, 200, 200),
    ("portal.results_json", "GET"): (LOGIN, 403, 403, 200, 200),
    # the 3D viewer of team A's finished run (its logs hold no state log: nothing to replay;
    # nothing live: it has ended). A live run's refusals are in tests/viewer.
    ("viewer.view", "GET"): (LOGIN, 200, 404, 200, 200),
    ("viewer.scene", "GET"): (LOGIN, 200, 404, 200, 200),
    ("viewer.frames", "GET"): (LOGIN, 409, 404, 409, 409),
    ("viewer.live_frames", "GET"): (LOGIN, 409, 404, 409, 409),
    ("api_viewer.Scene", "GET"): (401, 200, 404, 200, 200),
    ("api_viewer.Frames", "GET"): (401, 409, 404, 409, 409),
    ("api_viewer.LiveFrames", "GET"): (401, 409, 404, 409, 409),
    ("api_competition.Tasks", "GET"): (401, 200, 200, 200, 200),
    ("api_competition.Tasks", "POST"): (401, 403, 403, 201, 201),
    ("api_competition.OpenTasks", "GET"): (401, 200, 200, 200, 200),
    ("api_competition.TaskById", "GET"): (401, 200, 404, 200, 200),
    ("api_competition.TaskById", "DELETE"): (401, 403, 403, 204, 204),
    ("api_competition.StartRun", "POST"): (401, 202, 403, 202, 202),
    ("api_competition.RunLive", "GET"): (401, 200, 404, 200, 200),
    ("api_competition.Season", "GET"): (401, 403, 403, 200, 200),
    ("api_competition.Season", "POST"): (401, 403, 403, 201, 201),
    ("api_competition.Runs", "GET"): (401, 200, 200, 200, 200),
    ("api_competition.RunById", "GET"): (401, 200, 404, 200, 200),
    ("api_competition.StopRun", "POST"): (401, 409, 404, 409, 409),
    ("api_competition.RunLog", "GET"): (401, 200, 404, 200, 200),
    ("api_competition.Leaderboard", "GET"): (401, 200, 200, 200, 200),
    # the portal's integrity side: officers; uploads take an instance's upload token, no user's
    ("portal_ingest.refusals", "GET"): (LOGIN, 403, 403, 200, 200),
    ("portal_ingest.review_run", "POST"): (LOGIN, 403, 403, 302, 302),
    ("api_portal.Refusals", "GET"): (401, 403, 403, 200, 200),
    ("api_portal.RunReview", "PATCH"): (401, 403, 403, 200, 200),
    ("api_portal_ingest.UploadedRun", "PUT"): (401, 401, 401, 401, 401),
    ("api_portal_ingest.UploadedRun", "GET"): (401, 401, 401, 401, 401),
    ("api_portal_ingest.UploadedLog", "PUT"): (401, 401, 401, 401, 401),
    ("api_portal_ingest.UploadedLog", "GET"): (401, 401, 401, 401, 401),
    ("api_portal_ingest.CompletedUpload", "POST"): (401, 401, 401, 401, 401),
    # team instances (a fresh spare each time): admins only
    ("team_instances.index", "GET"): (LOGIN, 403, 403, 403, 200),
    ("team_instances.deploy", "POST"): (LOGIN, 403, 403, 403, 400),  # an empty form
    ("team_instances.show", "GET"): (LOGIN, 403, 403, 403, 200),
    ("team_instances.assign", "POST"): (LOGIN, 403, 403, 403, 400),  # no team chosen
    ("team_instances.terminate", "POST"): (LOGIN, 403, 403, 403, 302),
    ("team_instances.provider_settings", "POST"): (LOGIN, 403, 403, 403, 400),  # no inventory
    ("api_team_instances.TeamInstances", "GET"): (401, 403, 403, 403, 200),
    ("api_team_instances.TeamInstances", "POST"): (401, 403, 403, 403, 202),
    ("api_team_instances.TeamInstanceById", "GET"): (401, 403, 403, 403, 200),
    ("api_team_instances.TeamInstanceById", "PATCH"): (401, 403, 403, 403, 200),
    ("api_team_instances.TeamInstanceById", "DELETE"): (401, 403, 403, 403, 202),
    ("api_team_instances.InstanceHealth", "GET"): (401, 403, 403, 403, 200),
    # notifications: webhooks are admins'; anyone logged in chooses their own run e-mails
    ("notifications.webhooks", "GET"): (LOGIN, 403, 403, 403, 200),
    ("notifications.add_webhook", "POST"): (LOGIN, 403, 403, 403, 400),  # an empty form
    ("notifications.remove_webhook", "POST"): (LOGIN, 403, 403, 403, 302),
    ("notifications.run_emails", "POST"): (LOGIN, 302, 302, 302, 302),
    ("api_notifications.Webhooks", "GET"): (401, 403, 403, 403, 200),
    ("api_notifications.Webhooks", "POST"): (401, 403, 403, 403, 201),
    ("api_notifications.WebhookById", "DELETE"): (401, 403, 403, 403, 204),
    ("api_notifications.Deliveries", "GET"): (401, 403, 403, 403, 200),
    # this app has team instances by now (the entries above): a master takes no desired state
    ("api_team_instances.DesiredState", "PUT"): (401, 403, 403, 403, 409),
    ("worlds.index", "GET"): (LOGIN, 403, 403, 403, 200),
    ("worlds.upload", "POST"): (LOGIN, 403, 403, 403, 400),  # nothing uploaded
    ("worlds.show", "GET"): (LOGIN, 403, 403, 403, 200),
    ("worlds.download", "GET"): (LOGIN, 403, 403, 403, 200),
    ("api_worlds.Worlds", "GET"): (401, 403, 403, 403, 200),
    ("api_worlds.WorldByName", "GET"): (401, 403, 403, 403, 200),
    ("api_worlds.WorldByName", "PUT"): (401, 403, 403, 403, 200),
    ("api_team_instances.InstanceProvider", "PUT"): (401, 403, 403, 403, 200),
    ("api_team_instances.LaunchThrough", "POST"): (401, 403, 403, 403, 200),
    ("team_instances.launch_all", "POST"): (LOGIN, 403, 403, 403, 302),  # the defaults: vrc
    ("api_providers.ProviderSettings", "PUT"): (401, 403, 403, 403, 200),
    # monitoring: health is public; readiness is public and tells no secret (no worker has
    # been heard from here: 503); metrics answer by network or token, not by person: the
    # test client calls from loopback (refusals elsewhere: tests/monitoring/test_metrics.py)
    ("monitoring.healthz", "GET"): (200, 200, 200, 200, 200),
    ("monitoring.readyz", "GET"): (503, 503, 503, 503, 503),
    ("monitoring.metrics", "GET"): (200, 200, 200, 200, 200),
}

IGNORED_ENDPOINTS = {"static"}
INVENTORY = inventory()
LOGOUT = ("auth.logout", "POST")


def _bodies(team_id: int) -> dict[tuple[str, str], Callable[[], dict[str, Any]]]:
    """Valid JSON bodies, so that the API's answers show authorization, not validation."""
    return {
        ("api_account.Tokens", "POST"): lambda: {"name": "matrix"},
        ("api_account.SshKeys", "POST"): lambda: {"generate": True},
        ("api_constellations.ConstellationById", "PATCH"): lambda: {"team_sudo": True},
        ("api_people.Teams", "POST"): lambda: {"name": f"Matrix {next(_seq)}"},
        ("api_people.TeamById", "PATCH"): lambda: {"name": "Team A"},
        ("api_people.Users", "POST"): lambda: {
            "email": f"m{next(_seq)}@example.org",
            "team_id": team_id,
        },
        ("api_people.UserById", "PATCH"): lambda: {"name": "Renamed"},
        ("api_jobs.Jobs", "POST"): lambda: {"kind": "diagnostics"},
        ("api_constellations.Constellations", "POST"): lambda: {
            "name": f"matrix-{next(_seq)}",
            "kind": "vrc",
            "team_id": team_id,
        },
        ("api_competition.Tasks", "POST"): lambda: {
            "name": f"Matrix {next(_seq)}",
            "world": "vrc_task_1",
            "start": "2030-01-01 09:00",
            "stop": "2030-01-01 12:00",
            "team_ids": [team_id],
        },
        ("api_team_instances.TeamInstances", "POST"): lambda: {"name": f"mx-{next(_seq)}"},
        ("api_team_instances.TeamInstanceById", "PATCH"): lambda: {"team_id": team_id},
        ("api_team_instances.DesiredState", "PUT"): lambda: {
            "team": None,
            "users": [],
            "tasks": [],
        },
        ("api_worlds.WorldByName", "PUT"): lambda: {"document": shipped_document("vrc_task_1")},
        ("api_team_instances.InstanceProvider", "PUT"): lambda: {
            "provider": "servers",
            "settings": {"inventory": INVENTORY},
        },
        ("api_team_instances.LaunchThrough", "POST"): lambda: {"kind": "simple"},
        ("api_notifications.Webhooks", "POST"): lambda: {
            "url": "https://hooks.example.org/cloudsim",
            "secret": "a-matrix-secret-of-length",
        },
        ("api_providers.ProviderSettings", "PUT"): lambda: {"settings": {"inventory": INVENTORY}},
        ("api_competition.Season", "POST"): lambda: {
            "yaml": "tasks: [{name: Matrix season, world: vrc_task_2, "
            f"start: '2030-01-0{next(_seq) % 9 + 1} 09:00', stop: '2030-01-10 09:00'}}]"
        },
    }


def _routes(app: Flask) -> set[tuple[str, str]]:
    return {
        (rule.endpoint, method)
        for rule in app.url_map.iter_rules()
        if rule.endpoint not in IGNORED_ENDPOINTS
        for method in rule.methods - {"HEAD", "OPTIONS"}  # type: ignore[operator]
    }


def test_every_route_is_in_the_matrix(app: Flask) -> None:
    routes = _routes(app)
    missing = sorted(routes - MATRIX.keys())
    stale = sorted(MATRIX.keys() - routes)
    assert not missing, f"routes without an authorization entry: {missing}"
    assert not stale, f"matrix entries for routes that no longer exist: {stale}"


def _url(
    app: Flask,
    endpoint: str,
    team_a: Team,
    user_a: User,
    job_id: str,
    constellation_id: int,
    tmp: Path,
) -> str:
    """Build the URL, pointing every id at something of team A (fresh where it gets deleted)."""
    rule = next(r for r in app.url_map.iter_rules() if r.endpoint == endpoint)
    values: dict[str, Any] = {}
    if "team_id" in rule.arguments:
        values["team_id"] = team_a.id
    if "user_id" in rule.arguments:
        values["user_id"] = make_user(Role.USER, team_a).id
    if "token_id" in rule.arguments:
        values["token_id"] = issue_token(user_a, "victim").token.id
    if "key_id" in rule.arguments:
        values["key_id"] = generate_key(user_a, "victim").key.id
    if "job_id" in rule.arguments:
        values["job_id"] = job_id
    if "webhook_id" in rule.arguments:
        hook = Webhook(url="https://hooks.example.org/victim", secret="a-victim-secret-16+")
        db.session.add(hook)
        db.session.commit()
        values["webhook_id"] = hook.id
    if "instance_id" in rule.arguments:
        deployed = team_instances.deploy(SYSTEM, name=f"mx-{next(_seq)}", provider="local")
        values["instance_id"] = deployed[0][0].id
    if "name" in rule.arguments:
        # a provider's name, or a world's
        values["name"] = "servers" if endpoint.startswith("api_providers") else "vrc_task_1"
    if "phase_id" in rule.arguments:
        values["phase_id"] = _phase().id
    if "remote_run_id" in rule.arguments:
        values["remote_run_id"] = 1
    if "filename" in rule.arguments:
        values["filename"] = "score.jsonl"
    if "ref" in rule.arguments:
        values["ref"] = constellation_id
    if {"task_id", "run_id"} & set(rule.arguments):
        ready_constellation(constellation_id)
        values["task_id"] = open_task(team_a.id).id
        run = finished_run(open_task(team_a.id), constellation_id, tmp)
        values.update(run_id=run.id, artifact_id=run.artifacts[0].id)
        values = {k: v for k, v in values.items() if k in rule.arguments}
    with app.test_request_context():
        from flask import url_for

        return url_for(endpoint, **values)


def _phase() -> Phase:
    """Add a phase open now, with hidden scores, and commit it."""
    now = utcnow()
    spec = PhaseSpec(
        name=f"phase {next(_seq)}",
        window_start=now - timedelta(minutes=1),
        window_stop=now + timedelta(hours=1),
        worlds=(("vrc_task_1", 1),),
        scores_hidden=True,
    )
    phase = save_phase(SYSTEM, spec)
    db.session.commit()
    return phase


@pytest.mark.parametrize("persona", PERSONAS)
def test_route_answers_match_the_matrix(
    app: Flask, people: dict[str, User | None], persona: str, tmp_path: Path
) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    team_a = people["user_a"].team  # type: ignore[union-attr]
    job_id = enqueue("diagnostics", SYSTEM, team_id=team_a.id).id
    constellation = Constellation(
        name="team-a-vrc",
        kind="vrc",
        provider="local",
        team_id=team_a.id,
        state=ConstellationState.READY,
    )
    db.session.add(constellation)
    db.session.commit()
    user = people[persona]
    bodies = _bodies(team_a.id)
    headers = token_for(user) if user is not None else {}
    wrong = []
    client = app.test_client()
    if user is not None:
        log_in(client, user)
    # Logging out ends the session the other visits use: visit it last.
    for (endpoint, method), expected in sorted(MATRIX.items(), key=lambda i: i[0] == LOGOUT):
        url = _url(app, endpoint, team_a, people["user_a"], job_id, constellation.id, tmp_path)  # type: ignore[arg-type]
        api = url.startswith("/api/")
        body = bodies.get((endpoint, method), lambda: {})()
        if api:
            response = client.open(url, method=method, json=body, headers=headers)
        else:
            response = client.open(url, method=method, data=body)
        status = expected[PERSONAS.index(persona)]
        if response.status_code != status:
            wrong.append(f"{method} {url}: {response.status_code}, expected {status}")
        db.session.rollback()
    assert not wrong, f"{persona}:\n" + "\n".join(wrong)
