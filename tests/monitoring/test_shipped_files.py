"""The shipped alert rules pass `promtool check rules`; the rules and the Grafana dashboard
query only metrics CloudSim exports."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml
from flask import Flask
from prometheus_client.parser import text_string_to_metric_families

from cloudsim.monitoring import heartbeats
from provisioners.remote.operations.templates import MachineTemplates
from tests.monitoring.support import measurable_season

METRIC = re.compile(r"\bcloudsim_[a-z_]+\b")


@pytest.fixture
def shipped(pytestconfig: pytest.Config) -> Path:
    return pytestconfig.rootpath / "deploy" / "monitoring"


@pytest.fixture
def exported(app: Flask) -> set[str]:
    """Every sample name a CloudSim with a season in progress exports."""
    measurable_season()
    url = app.config["CLOUDSIM"].effective_redis_url
    heartbeats.note(url, heartbeats.WORKER + "cloudsim@box")
    heartbeats.note(url, heartbeats.BEAT)
    client = app.test_client()
    client.get("/healthz")
    text = client.get("/metrics").get_data(as_text=True)
    return {s.name for f in text_string_to_metric_families(text) for s in f.samples}


def test_promtool_accepts_the_alert_rules(shipped: Path) -> None:
    promtool = shutil.which("promtool")
    if promtool is None:
        pytest.skip("Debian's prometheus (promtool) is not installed")
    checked = subprocess.run(
        [promtool, "check", "rules", str(shipped / "cloudsim-alerts.yml")],
        capture_output=True,
        text=True,
    )
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "SUCCESS: 8 rules found" in checked.stdout
    config = subprocess.run(
        [promtool, "check", "config", str(shipped / "prometheus.yml")],
        capture_output=True,
        text=True,
    )
    assert config.returncode == 0, config.stdout + config.stderr


def test_alert_rules_cover_the_issues_and_name_exported_metrics(
    shipped: Path, exported: set[str]
) -> None:
    rules = yaml.safe_load((shipped / "cloudsim-alerts.yml").read_text())["groups"][0]["rules"]
    names = {rule["alert"] for rule in rules}
    assert {
        "CloudSimWorkerSilent",
        "CloudSimJobStuck",
        "CloudSimRunBelowRealTime",
        "CloudSimInstanceUnreachable",
        "CloudSimUploadBacklogGrowing",
        "CloudSimMachineHoursNearBudget",
    } <= names
    for rule in rules:
        used = set(METRIC.findall(rule["expr"]))
        assert used and used <= exported, f"{rule['alert']}: {sorted(used - exported)}"


def test_dashboard_panels_query_only_exported_metrics(shipped: Path, exported: set[str]) -> None:
    dashboard = json.loads((shipped / "grafana-dashboard.json").read_text())
    assert dashboard["uid"] and dashboard["panels"]
    used: set[str] = set()
    for panel in dashboard["panels"]:
        assert panel["targets"], f"panel {panel['title']!r} has no query"
        for target in panel["targets"]:
            names = set(METRIC.findall(target["expr"]))
            assert names, f"panel {panel['title']!r} queries no CloudSim metric"
            assert names <= exported, f"{panel['title']!r}: {sorted(names - exported)}"
            used |= names
    # the season at a glance: every family of issue 28's list has a panel
    for family in (
        "cloudsim_jobs",
        "cloudsim_queue_messages",
        "cloudsim_run_real_time_factor",
        "cloudsim_run_bits_left",
        "cloudsim_machines",
        "cloudsim_team_instance_up",
        "cloudsim_portal_upload_backlog_bytes",
        "cloudsim_http_request_duration_seconds_bucket",
        "cloudsim_worker_heartbeat_timestamp_seconds",
    ):
        assert family in used, family


def test_the_cloudsim_kinds_unit_waits_for_readiness() -> None:
    unit = MachineTemplates().render(
        "cloudsim/cloudsim.service.j2",
        {
            "constellation": "team-a",
            "env_file": "/etc/cloudsim/env",
            "root": "/opt/cloudsim",
            "venv": "/opt/cloudsim/venv",
        },
    )
    lines = unit.splitlines()
    assert "ExecStart=/opt/cloudsim/venv/bin/cloudsim up" in lines
    # started means ready (the /readyz checks); a part still down is reported, not fatal
    assert "ExecStartPost=-/opt/cloudsim/venv/bin/cloudsim status --wait 120" in lines
    timeout = next(line for line in lines if line.startswith("TimeoutStartSec="))
    assert int(timeout.split("=")[1]) > 120
    assert "{#" not in unit and "#}" not in unit
