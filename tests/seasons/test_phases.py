"""A season's phases: the YAML both ways, entry by qualification, limits, ranking, reveal."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.models import Phase, Run, RunState, Task, Team, User, Verification, utcnow
from cloudsim.seasons import service
from cloudsim.seasons.rules import RuleRefused, check_run_limits
from tests.conftest import csrf_token, log_in, token_for


def _at(hours: float) -> str:
    return (utcnow() + timedelta(hours=hours)).strftime("%Y-%m-%d %H:%M")


def season(practice_limits: str = "{per_task: 2, per_day: 3, total: 4, at_once: 1}") -> str:
    """Three phases as docs/seasons.md writes them: practice open now, two later ones."""
    return f"""\
time_zone: UTC
phases:
  - name: practice
    start: {_at(-1)}
    stop: {_at(5)}
    worlds:
      - {{world: vrc_task_1, configs: [1, 2]}}
      - {{world: vrc_task_2, configs: [1]}}
    limits: {practice_limits}
    ranking: false
  - name: qualification
    start: {_at(24)}
    stop: {_at(30)}
    worlds:
      - {{world: vrc_task_3, configs: [1]}}
    scores: hidden
  - name: competition
    start: {_at(48)}
    stop: {_at(72)}
    worlds:
      - {{world: vrc_task_1, configs: [3]}}
    entry: {{after: qualification, min_score: 2}}
    limits: {{at_once: 1}}
"""


def test_a_three_phase_season_through_the_documented_api(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    created = client.post("/api/v1/schedule", json={"yaml": season()}, headers=officer)
    assert created.status_code == 201, created.json
    # practice and qualification for both teams; competition waits for qualification to close
    assert len(created.json) == 2 * (3 + 1)
    assert {t["name"] for t in created.json} >= {"practice: vrc_task_1 #2"}
    phases = client.get("/api/v1/phases", headers=token_for(people["user_a"])).json  # type: ignore[arg-type]
    assert [p["name"] for p in phases] == ["practice", "qualification", "competition"]
    practice, qualification, competition = phases
    assert practice["limits"] == {"per_task": 2, "per_day": 3, "total": 4, "at_once": 1}
    assert practice["counts_in_ranking"] is False and qualification["scores"] == "hidden"
    assert competition["entry_after"] == "qualification"
    assert competition["entry_min_score"] == 2
    assert {"world": "vrc_task_1", "config": 2} in practice["worlds"]
    # a team sees its own practice tasks (open now), not the later phases' yet
    mine = client.get("/api/v1/tasks", headers=token_for(people["user_a"])).json  # type: ignore[arg-type]
    assert len(mine) == 3 and {t["phase_id"] for t in mine} == {practice["id"]}
    # the export carries the phases, and importing it again changes nothing
    exported = client.get("/api/v1/schedule", headers=officer).json["yaml"]
    assert "phases:" in exported and "min_score: 2" in exported
    again = client.post("/api/v1/schedule", json={"yaml": exported}, headers=officer)
    assert again.status_code == 201 and again.json == []
    assert client.get("/api/v1/schedule", headers=officer).json["yaml"] == exported
    # too early to know who qualified: the refusal says when
    early = client.post(f"/api/v1/phases/{competition['id']}/schedule", headers=officer)
    assert early.status_code == 409 and "closes at" in early.json["message"]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("    ranking: false\n", "    ranking: no way\n"), "phase 1 (practice): ranking"),
        (("per_task: 2", "per_task: 0"), "phase 1 (practice): limits: per_task must be"),
        (("per_task: 2", "per_tusk: 2"), "phase 1 (practice): limits: unknown per_tusk"),
        (("configs: [1]", "configs: [9]"), "phase 1 (practice): worlds:"),
        (("world: vrc_task_3", "world: vrc_task_9"), "phase 2 (qualification): worlds:"),
        (("    scores: hidden\n", "    scores: secret\n"), "phase 2 (qualification): scores"),
        (("after: qualification", "after: finals"), "phase 3 (competition): entry: after"),
        (("min_score: 2", "min_score: two"), "phase 3 (competition): entry: min_score"),
        (("  - name: qualification", "  - name: practice"), "name: used by two phases"),
        (("    stop: ", "    stopp: "), "phase 1 (practice): unknown keys stopp"),
    ],
)
def test_every_bad_field_is_named_and_nothing_changes(
    app: Flask,
    people: dict[str, User | None],
    team_a: Team,
    change: tuple[str, str],
    message: str,
) -> None:
    text = season().replace(*change, 1)
    assert text != season()
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    answer = client.post("/api/v1/schedule", json={"yaml": text}, headers=officer)
    assert answer.status_code == 400, answer.json
    assert message in answer.json["message"]
    assert db.session.scalar(select(func.count()).select_from(Phase)) == 0
    assert db.session.scalar(select(func.count()).select_from(Task)) == 0


def _run(task: Task, score: int = 0, state: RunState = RunState.FINISHED, **fields: object) -> Run:
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        state=state,
        score=score,
        end_reason="time_limit",
        verification=Verification.VERIFIED,
        **fields,
    )
    db.session.add(run)
    db.session.commit()
    return run


def _tasks(team: Team, phase_name: str) -> list[Task]:
    phase = service.find_phase(SYSTEM, phase_name)
    query = select(Task).where(Task.team_id == team.id, Task.phase_id == phase.id)
    return list(db.session.scalars(query.order_by(Task.order)))


def _import(text: str) -> None:
    from cloudsim.competition.season import import_season

    import_season(SYSTEM, text)
    db.session.commit()


def test_qualification_admits_teams_at_the_minimum_score_and_not_below(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    _import(season())
    (task_a,), (task_b,) = _tasks(team_a, "qualification"), _tasks(team_b, "qualification")
    _run(task_a, score=2)  # exactly the minimum
    _run(task_b, score=1)  # one short
    qualification = service.find_phase(SYSTEM, "qualification")
    qualification.window_start = utcnow() - timedelta(hours=2)
    qualification.window_stop = utcnow() - timedelta(seconds=1)
    db.session.commit()
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    competition = service.find_phase(SYSTEM, "competition").id
    user = client.post(
        f"/api/v1/phases/{competition}/schedule", headers=token_for(people["user_a"])
    )  # type: ignore[arg-type]
    assert user.status_code == 403
    made = client.post(f"/api/v1/phases/{competition}/schedule", headers=officer)
    assert made.status_code == 201, made.json
    assert [t["team_id"] for t in made.json] == [team_a.id]
    again = client.post(f"/api/v1/phases/{competition}/schedule", headers=officer)
    assert again.status_code == 201 and again.json == []  # idempotent


def test_each_limit_holds_at_its_boundary(app: Flask, team_a: Team, team_b: Team) -> None:
    _import(season("{per_task: 2, total: 3, at_once: 1}"))
    drive_1, drive_2, walk = _tasks(team_a, "practice")
    now = utcnow()
    check_run_limits(drive_1, now)  # nothing run yet
    live = _run(drive_1, state=RunState.RUNNING)
    with pytest.raises(RuleRefused, match="at_once") as refused:
        check_run_limits(walk, now)
    assert refused.value.retry_at is not None  # when the live run's time limit is up
    live.state = RunState.FINISHED
    db.session.commit()
    check_run_limits(drive_2, now)  # one run of vrc_task_1 so far: a second is allowed
    _run(drive_2)
    with pytest.raises(RuleRefused, match=r"per_task.*2 run.*vrc_task_1") as refused:
        check_run_limits(drive_1, now)
    assert refused.value.retry_at is None
    _run(drive_1, state=RunState.ERROR)  # a failed start is no attempt
    check_run_limits(walk, now)  # two runs in all: a third is allowed
    _run(walk)
    with pytest.raises(RuleRefused, match="total"):
        check_run_limits(walk, now)
    # another team's runs count against nobody else
    check_run_limits(_tasks(team_b, "practice")[0], now)


def test_a_day_limit_counts_days_in_the_phase_zone_and_says_when_to_return(
    app: Flask, team_a: Team
) -> None:
    _import(season("{per_day: 2}").replace("time_zone: UTC", "time_zone: Asia/Tokyo"))
    task, other, earlier = _tasks(team_a, "practice")
    phase = task.phase
    assert phase is not None
    # 14:59 UTC is 23:59 in Tokyo; the day there ends at 15:00 UTC
    now = datetime(2030, 1, 1, 14, 59, tzinfo=UTC)
    phase.window_start, phase.window_stop = now - timedelta(days=1), now + timedelta(days=2)
    _run(task, started_at=now - timedelta(hours=1))
    check_run_limits(task, now)  # one today: a second is allowed
    # 00:30 on the same day in Tokyo, though the day before in UTC: it counts
    _run(other, started_at=datetime(2029, 12, 31, 15, 30, tzinfo=UTC))
    # 23:30 the day before in Tokyo: it does not
    _run(earlier, started_at=datetime(2029, 12, 31, 14, 30, tzinfo=UTC))
    with pytest.raises(RuleRefused, match=r"per_day.*made 2 today") as refused:
        check_run_limits(task, now)
    assert refused.value.retry_at == datetime(2030, 1, 1, 15, 0, tzinfo=UTC)
    check_run_limits(task, now + timedelta(minutes=1))  # a new day in Tokyo


def test_a_team_is_refused_a_start_over_the_api_with_the_rule_and_when(
    app: Flask, people: dict[str, User | None], team_a: Team
) -> None:
    _import(season("{total: 1}"))
    first, second, _ = _tasks(team_a, "practice")
    _run(first)
    client = app.test_client()
    answer = client.post(
        f"/api/v1/tasks/{second.id}/runs",
        json={},
        headers=token_for(people["user_a"]),  # type: ignore[arg-type]
    )
    assert answer.status_code == 403
    assert "rule total" in answer.json["message"]
    assert "no later start is allowed in this phase" in answer.json["message"]
    assert db.session.scalar(select(func.count()).select_from(Run)) == 1


def test_the_ranking_leaves_out_unranked_phases_and_hidden_scores_until_revealed(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    _import(season())
    _run(_tasks(team_a, "practice")[0], score=4)  # practice does not count
    _run(_tasks(team_b, "qualification")[0], score=3)  # hidden until revealed
    client = app.test_client()
    user, officer = (token_for(people[p]) for p in ("user_a", "officer"))  # type: ignore[arg-type]

    def points(headers: dict[str, str]) -> dict[str, int]:
        board = client.get("/api/v1/leaderboard", headers=headers).json
        return {row["team"]: row["checkpoints"] for row in board}

    assert points(officer) == {"Team A": 0, "Team B": 3}
    assert points(user) == {"Team A": 0, "Team B": 0}
    qualification = service.find_phase(SYSTEM, "qualification").id
    assert client.post(f"/api/v1/phases/{qualification}/reveal", headers=user).status_code == 403
    revealed = client.post(f"/api/v1/phases/{qualification}/reveal", headers=officer)
    assert revealed.status_code == 200 and revealed.json["revealed_at"]
    assert points(user) == {"Team A": 0, "Team B": 3}
    practice = service.find_phase(SYSTEM, "practice").id
    live = client.post(f"/api/v1/phases/{practice}/reveal", headers=officer)
    assert live.status_code == 409 and "shown live" in live.json["message"]


def test_an_officer_imports_phases_and_reveals_scores_through_the_pages(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get("/tasks").get_data(as_text=True)
    imported = client.post(
        "/tasks/import",
        data={"csrf_token": csrf_token(page), "schedule_text": season()},
        follow_redirects=True,
    )
    assert "Imported the schedule: 8 new task(s)." in imported.get_data(as_text=True)
    page = client.get("/phases").get_data(as_text=True)
    assert "teams with at least 2 point(s) in qualification" in page
    assert "2 per task, 3 per day, 4 total, 1 at once" in page
    qualification = service.find_phase(SYSTEM, "qualification").id
    assert f'action="/phases/{qualification}/reveal"' in page
    revealed = client.post(
        f"/phases/{qualification}/reveal",
        data={"csrf_token": csrf_token(page)},
        follow_redirects=True,
    )
    assert "The scores of qualification are shown to the teams." in revealed.get_data(as_text=True)
    assert f'action="/phases/{qualification}/reveal"' not in revealed.get_data(as_text=True)
    team_page = app.test_client()
    log_in(team_page, people["user_a"])  # type: ignore[arg-type]
    seen = team_page.get("/phases").get_data(as_text=True)
    assert "revealed" in seen and "Schedule its tasks" not in seen
