"""A real Prometheus scrapes a real CloudSim (`cloudsim up`) with a live run: the values and a
firing alert read back through Prometheus' own HTTP API."""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import requests

from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.extensions import db
from tests.monitoring.support import UPLINK_CAP, Season, measurable_season
from tests.support.servers import free_port, wait_for
from tests.support.up import cloudsim_up

PROMETHEUS = shutil.which("prometheus")
pytestmark = pytest.mark.skipif(PROMETHEUS is None, reason="Debian's prometheus is not installed")


@pytest.fixture
def cloudsim(tmp_path: Path, pytestconfig: pytest.Config) -> Iterator[tuple[str, Season]]:
    """Run `cloudsim up` (two web processes) with a live run in its database; yield its URL."""
    settings = {
        "CLOUDSIM_WEB_WORKERS": "2",
        "CLOUDSIM_ADMIN_PASSWORD": "a password for the prometheus test",
        "CLOUDSIM_LOG_LEVEL": "WARNING",
    }
    with cloudsim_up(tmp_path, pytestconfig.rootpath, **settings) as up:
        app = create_app(Config.from_env(up.env))
        with app.app_context():
            season = measurable_season()
            db.session.remove()
            db.engine.dispose()
        yield up.address, season


@pytest.fixture
def prometheus(
    tmp_path: Path, cloudsim: tuple[str, Season], pytestconfig: pytest.Config
) -> Iterator[str]:
    """Run Prometheus scraping the CloudSim every second, with the shipped alert rules (their
    `for:` shortened to nothing, so a true condition fires at the next evaluation)."""
    shipped = pytestconfig.rootpath / "deploy" / "monitoring" / "cloudsim-alerts.yml"
    rules = tmp_path / "rules.yml"
    rules.write_text(re.sub(r"for: \S+", "for: 0s", shipped.read_text()))
    config = tmp_path / "prometheus.yml"
    config.write_text(
        # a scrape may take seconds on a loaded machine: a 1 s timeout would drop it
        "global: {scrape_interval: 3s, scrape_timeout: 3s, evaluation_interval: 1s}\n"
        f"rule_files: [{rules}]\n"
        "scrape_configs:\n"
        f"  - {{job_name: cloudsim, static_configs: [{{targets: ['{cloudsim[0]}']}}]}}\n"
    )
    port = free_port()
    with (tmp_path / "prometheus.log").open("wb") as out:
        process = subprocess.Popen(
            [
                str(PROMETHEUS),
                f"--config.file={config}",
                f"--storage.tsdb.path={tmp_path / 'tsdb'}",
                f"--web.listen-address=127.0.0.1:{port}",
            ],
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        process.terminate()
        process.wait(30)


def _query(prometheus: str, expr: str) -> list[dict[str, Any]]:
    try:
        answer = requests.get(f"{prometheus}/api/v1/query", params={"query": expr}, timeout=5)
    except requests.ConnectionError:
        return []  # not listening yet
    assert answer.json()["status"] == "success", answer.text
    return list(answer.json()["data"]["result"])


def _one(prometheus: str, expr: str) -> float:
    found = wait_for(lambda: _query(prometheus, expr), 120, f"Prometheus to have {expr}")
    assert isinstance(found, list) and len(found) == 1, found
    return float(found[0]["value"][1])


def test_prometheus_scrapes_a_live_run_and_fires_an_alert(
    cloudsim: tuple[str, Season], prometheus: str
) -> None:
    address, season = cloudsim
    # the worker and the beat are heard from: CloudSim reports itself ready
    wait_for(
        lambda: requests.get(f"http://{address}/readyz", timeout=60).status_code == 200,
        300,  # the worker and the web processes start slowly on a busy 2-core machine
        "GET /readyz to answer 200",
    )
    run = f'run_id="{season.run_id}",team="{season.team}"'
    assert 0.3 < _one(prometheus, f"cloudsim_run_real_time_factor{{{run}}}") < 0.51
    left = _one(prometheus, f'cloudsim_run_bits_left{{{run},direction="uplink"}}')
    assert left == UPLINK_CAP - 250_000
    assert _one(prometheus, 'cloudsim_runs{state="running"}') == 1
    assert _one(prometheus, 'cloudsim_machines{state="ready",provider="local"}') == 2
    assert _one(prometheus, 'cloudsim_team_instance_up{team_instance="team-instance-1"}') == 0
    assert _one(prometheus, "cloudsim_portal_upload_backlog_bytes") == 4000
    seen = _one(prometheus, "max(cloudsim_worker_heartbeat_timestamp_seconds)")
    assert time.time() - seen < 60
    assert time.time() - _one(prometheus, "cloudsim_beat_heartbeat_timestamp_seconds") < 60
    # the two gunicorn processes' request timings, summed (multiprocess mode)
    readyz = 'cloudsim_http_request_duration_seconds_count{route="/readyz",status="200"}'
    assert _one(prometheus, f"sum({readyz})") >= 1

    def firing() -> list[dict[str, Any]]:
        alerts = requests.get(f"{prometheus}/api/v1/alerts", timeout=5).json()["data"]["alerts"]
        return [
            alert
            for alert in alerts
            if alert["labels"]["alertname"] == "CloudSimRunBelowRealTime"
            and alert["state"] == "firing"
        ]

    alert = wait_for(firing, 120, "the below-real-time alert to fire")
    assert isinstance(alert, list)
    assert alert[0]["labels"]["run_id"] == str(season.run_id)
    assert alert[0]["labels"]["severity"] == "warning"
