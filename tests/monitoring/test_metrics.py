"""GET /metrics: who may read it, and the figures it reports for a season in progress."""

from __future__ import annotations

from collections.abc import Callable

from flask import Flask
from prometheus_client.parser import text_string_to_metric_families

from cloudsim.config import Config
from cloudsim.monitoring import heartbeats
from tests.conftest import running_app
from tests.monitoring.support import DOWNLINK_CAP, UPLINK_CAP, measurable_season

REMOTE = {"REMOTE_ADDR": "203.0.113.7"}
TOKEN = "metrics-token-for-tests-0123456789"


def samples(text: str) -> dict[tuple[str, frozenset[tuple[str, str]]], float]:
    """Return every sample of an exposition, keyed by name and labels."""
    return {
        (sample.name, frozenset(sample.labels.items())): sample.value
        for family in text_string_to_metric_families(text)
        for sample in family.samples
    }


def value(found: dict, name: str, **labels: str) -> float:  # type: ignore[type-arg]
    return float(found[(name, frozenset(labels.items()))])


def test_metrics_answer_loopback_and_the_token_only(make_config: Callable[..., Config]) -> None:
    with running_app(make_config(metrics_token=TOKEN)) as app:
        client = app.test_client()
        assert client.get("/metrics").status_code == 200  # the test client is 127.0.0.1
        assert client.get("/metrics", environ_base=REMOTE).status_code == 403
        wrong = {"Authorization": "Bearer not-the-token"}
        assert client.get("/metrics", environ_base=REMOTE, headers=wrong).status_code == 403
        right = {"Authorization": f"Bearer {TOKEN}"}
        assert client.get("/metrics", environ_base=REMOTE, headers=right).status_code == 200


def test_metrics_answer_a_configured_network(make_config: Callable[..., Config]) -> None:
    networks = ("203.0.113.0/24",)
    with running_app(make_config(metrics_networks=networks)) as app:
        client = app.test_client()
        assert client.get("/metrics", environ_base=REMOTE).status_code == 200
        assert client.get("/metrics").status_code == 403  # loopback is no longer listed


def test_metrics_report_jobs_runs_machines_instances_and_the_outbox(any_db_app: Flask) -> None:
    app = any_db_app
    season = measurable_season()
    heartbeats.note(app.config["CLOUDSIM"].effective_redis_url, "worker:cloudsim@box", at=1234.5)
    client = app.test_client()
    client.get("/healthz")
    found = samples(client.get("/metrics").get_data(as_text=True))
    run = {"run_id": str(season.run_id), "team": season.team}
    assert 0.49 < value(found, "cloudsim_run_real_time_factor", **run) < 0.51
    assert value(found, "cloudsim_run_bits_used", **run, direction="uplink") == 250_000
    assert value(found, "cloudsim_run_bits_left", **run, direction="uplink") == UPLINK_CAP - 250_000
    left = value(found, "cloudsim_run_bits_left", **run, direction="downlink")
    assert left == DOWNLINK_CAP - 2_000_000
    assert value(found, "cloudsim_runs", state="running") == 1
    assert value(found, "cloudsim_jobs", kind="launch", state="queued") == 1
    assert value(found, "cloudsim_jobs_lost", kind="launch") == 1
    assert value(found, "cloudsim_job_oldest_queued_seconds") >= 3599
    assert value(found, "cloudsim_job_duration_seconds_count", kind="diagnostics") == 1
    assert value(found, "cloudsim_job_duration_seconds_bucket", kind="diagnostics", le="5.0") == 0
    assert value(found, "cloudsim_job_duration_seconds_bucket", kind="diagnostics", le="15.0") == 1
    assert value(found, "cloudsim_constellations", state="ready", provider="local", kind="vrc") == 1
    assert value(found, "cloudsim_machines", state="ready", provider="local") == 2
    assert 5.99 < value(found, "cloudsim_team_machine_hours", team=season.team) < 6.01
    instance = {"team_instance": "team-instance-1", "team": season.team}
    assert value(found, "cloudsim_team_instance_up", **instance) == 0
    assert 599 < value(found, "cloudsim_team_instance_sync_lag_seconds", **instance) < 700
    assert value(found, "cloudsim_portal_uploads", state="pending") == 1
    assert value(found, "cloudsim_portal_upload_backlog_bytes") == 4000
    assert value(found, "cloudsim_queue_messages") == 0
    assert (
        value(found, "cloudsim_worker_heartbeat_timestamp_seconds", worker="cloudsim@box") == 1234.5
    )
    timed = {"route": "/healthz", "method": "GET", "status": "200"}
    assert value(found, "cloudsim_http_request_duration_seconds_count", **timed) >= 1
