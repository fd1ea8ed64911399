"""CLOUDSIM_RANK_UNVERIFIED: unverified runs rank (marked) or wait for their verification."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.runs import leaderboard
from cloudsim.config import Config, ConfigError
from cloudsim.extensions import db
from cloudsim.models import Role, Run, RunState, Verification, utcnow
from cloudsim.people.service import create_team
from tests.competition.support import open_task
from tests.conftest import log_in, make_user, running_app


def _finished(team_id: int, verification: Verification | None, score: int) -> None:
    task = open_task(team_id)
    db.session.add(
        Run(
            task_id=task.id,
            team_id=team_id,
            state=RunState.FINISHED,
            score=score,
            finished_at=utcnow(),
            verification=verification,
        )
    )
    db.session.commit()


def test_the_setting_is_read_from_the_environment(tmp_path: Path) -> None:
    for value, meant in (("false", False), ("true", True)):
        env = {"CLOUDSIM_INSTANCE_DIR": str(tmp_path), "CLOUDSIM_RANK_UNVERIFIED": value}
        assert Config.from_env(env).rank_unverified is meant
    assert Config.from_env({"CLOUDSIM_INSTANCE_DIR": str(tmp_path)}).rank_unverified is True
    with pytest.raises(ConfigError, match="CLOUDSIM_RANK_UNVERIFIED"):
        Config.from_env({"CLOUDSIM_INSTANCE_DIR": str(tmp_path), "CLOUDSIM_RANK_UNVERIFIED": "?"})


@pytest.mark.parametrize("rank_unverified", ["true", "false"])
def test_unverified_runs_rank_only_if_the_setting_says_so(
    make_config: Callable[..., Config], rank_unverified: str
) -> None:
    config = make_config(rank_unverified=rank_unverified == "true")
    with running_app(config) as app:
        team = create_team(SYSTEM, "Team A")
        _finished(team.id, Verification.VERIFIED, 1)
        _finished(team.id, None, 2)  # its logs not all in yet
        _finished(team.id, Verification.VERIFYING, 3)
        _finished(team.id, Verification.HELD, 4)
        _finished(team.id, Verification.ACCEPTED, 1)
        (standing,) = leaderboard(SYSTEM)
        if rank_unverified == "true":
            assert (standing.runs, standing.checkpoints, standing.unverified) == (4, 7, 2)
        else:
            assert (standing.runs, standing.checkpoints, standing.unverified) == (2, 2, 0)
        assert standing.held == 1
        client = app.test_client()
        log_in(client, make_user(Role.OFFICER))
        page = client.get("/leaderboard").get_data(as_text=True)
        assert "1 held for review" in page
        if rank_unverified == "true":
            assert "2 unverified" in page and "Runs are ranked while their replay" in page
        else:
            assert "Only runs verified by replay" in page
