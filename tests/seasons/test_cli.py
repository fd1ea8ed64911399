"""`cloudsim schedule import` with phases, then `cloudsim phase list|schedule|reveal`."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result

from tests.seasons.test_phases import season
from tests.support.cli import migrated_cli
from tests.support.servers import RedisServer


@pytest.fixture
def run(tmp_path: Path, redis_server: RedisServer, encryption_key: str) -> Callable[..., Result]:
    return migrated_cli(tmp_path / "instance", redis_server.url(0), encryption_key)


def test_phases_from_the_command_line(run: Callable[..., Result], tmp_path: Path) -> None:
    assert run("team", "create", "Team Seven").exit_code == 0
    path = tmp_path / "season.yaml"
    path.write_text(season())
    imported = run("schedule", "import", str(path))
    assert imported.exit_code == 0, imported.output
    assert "4 new task(s)" in imported.output  # practice (3) and qualification (1)
    listed = run("phase", "list", "--json")
    assert listed.exit_code == 0, listed.output
    phases = {p["name"]: p for p in json.loads(listed.output)}
    assert phases["practice"]["limits"] == {"per_task": 2, "per_day": 3, "total": 4, "at_once": 1}
    assert phases["competition"]["entry"] == "qualification >= 2"
    assert phases["qualification"]["scores"] == "hidden"
    early = run("phase", "schedule", "competition")
    assert early.exit_code != 0 and "closes at" in early.output
    assert run("phase", "schedule", "practice").output.strip() == "practice: 0 new task(s)"
    revealed = run("phase", "reveal", "qualification")
    assert revealed.exit_code == 0 and "shown to the teams" in revealed.output
    assert json.loads(run("phase", "list", "--json").output)[1]["scores"] == "revealed"
    missing = run("phase", "reveal", "finals")
    assert missing.exit_code != 0 and "phase 'finals' not found" in missing.output
    bad = tmp_path / "bad.yaml"
    bad.write_text(season().replace("scores: hidden", "scores: secret"))
    refused = run("schedule", "import", str(bad))
    assert refused.exit_code != 0 and "phase 2 (qualification): scores" in refused.output
