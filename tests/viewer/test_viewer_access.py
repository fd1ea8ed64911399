"""Who sees what of a run in 3D, and the live relay's throttle and viewer cap."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from drcsim.engine import RunOptions, Simulation
from drcsim.worlds import shipped_document
from flask import Flask
from flask.testing import FlaskClient

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.lifecycle import RunJob
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext
from cloudsim.models import Job, Role, Run, RunState, User
from cloudsim.people import service
from cloudsim.viewer import service as viewer_service
from cloudsim.viewer.live import _key, redis_client, relay_job, store_frame
from cloudsim.worlds.service import update_world
from tests.competition.support import finished_run, open_task, store_log
from tests.conftest import log_in, make_user, running_app, token_for
from tests.viewer.conftest import store_run


def _client(app: Flask, user: User | None) -> FlaskClient:
    client = app.test_client()
    if user is not None:
        log_in(client, user)
    return client


def test_a_team_replays_its_own_finished_run_and_nobody_elses(
    app: Flask, people: dict[str, User | None], run_logs: Path
) -> None:
    user_a, user_b = people["user_a"], people["user_b"]
    assert user_a is not None and user_a.team is not None
    run = store_run(user_a.team, run_logs)
    mine, theirs = _client(app, user_a), _client(app, user_b)
    assert mine.get(f"/runs/{run.id}/view").status_code == 200
    scene = mine.get(f"/runs/{run.id}/view/scene").get_json()
    assert scene["run"]["mode"] == "replay"
    assert [m["kind"] for m in scene["marks"]] == ["checkpoint", "run_end"]
    body = mine.get(f"/runs/{run.id}/view/frames?start=2&seconds=1").get_json()
    assert [f["step"] for f in body["frames"]][:2] == [2010, 2040] and len(body["frames"]) == 33
    for path in ("", "/scene", "/frames?start=0&seconds=1", "/live"):
        assert theirs.get(f"/runs/{run.id}/view{path}").status_code == 404
    assert _client(app, None).get(f"/runs/{run.id}/view").status_code == 302
    # a finished run has nothing live
    officer = _client(app, people["officer"])
    assert officer.get(f"/runs/{run.id}/view/live").status_code == 409


@pytest.mark.parametrize(
    "query", ["start=abc", "start=nan", "start=-1", "seconds=0", "seconds=31", "seconds=inf"]
)
def test_bad_replay_ranges_are_refused(
    app: Flask, people: dict[str, User | None], run_logs: Path, query: str
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    run = store_run(user_a.team, run_logs)
    response = _client(app, user_a).get(f"/runs/{run.id}/view/frames?{query}")
    assert response.status_code == 400


def test_extreme_but_valid_replay_ranges_answer_no_frames(
    app: Flask, people: dict[str, User | None], run_logs: Path
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    run = store_run(user_a.team, run_logs)
    client, token = _client(app, user_a), token_for(user_a)
    for query in ("start=1e308&seconds=30", "seconds=1e-300", "start=8.99&seconds=0.000001"):
        for answer in (
            client.get(f"/runs/{run.id}/view/frames?{query}"),
            client.get(f"/api/v1/runs/{run.id}/view/frames?{query}", headers=token),
        ):
            assert answer.status_code == 200 and answer.get_json()["frames"] == [], query


def test_a_team_gets_no_live_view_of_its_own_running_run(
    app: Flask, people: dict[str, User | None], run_logs: Path
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    run = store_run(user_a.team, run_logs, RunState.RUNNING)
    team = _client(app, user_a)
    for path in ("", "/scene", "/live", "/frames"):
        response = team.get(f"/runs/{run.id}/view{path}")
        assert response.status_code == 403, path
    assert "officers only" in team.get(f"/runs/{run.id}/view").get_data(as_text=True)
    officer = _client(app, people["officer"])
    assert officer.get(f"/runs/{run.id}/view").status_code == 200
    # officers replay only finished runs
    assert officer.get(f"/runs/{run.id}/view/frames").status_code == 409


def test_live_viewers_are_throttled_capped_and_share_one_relay(
    make_config: Callable[..., Config], run_logs: Path
) -> None:
    config = make_config(viewer_max_live=2, viewer_poll_ms=60_000)
    with running_app(config) as app:
        team = service.create_team(SYSTEM, "Team A")
        officers = [make_user(Role.OFFICER) for _ in range(2)]
        run = store_run(team, run_logs, RunState.RUNNING)
        first, second = (_client(app, officer) for officer in officers)
        url = f"/runs/{run.id}/view/live"
        answer = first.get(f"{url}?viewer=tab1")
        assert answer.status_code == 200 and answer.get_json()["frames"] == []
        assert first.get(f"{url}?viewer=tab1").status_code == 429
        assert second.get(f"{url}?viewer=tab2").status_code == 200
        refused = second.get(f"{url}?viewer=tab3")
        assert refused.status_code == 503 and "live viewers" in refused.get_data(as_text=True)
        relays = db.session.scalars(db.select(Job).where(Job.kind == "viewer.relay")).all()
        assert len(relays) == 1 and relays[0].target_id == run.id
        # frames the relay buffers reach the viewers, newer than what they have
        for step in (1000, 1100):
            store_frame(redis_client(), run.id, {"t": step / 1000, "step": step, "poses": {}}, 2)
        redis_client().delete(_key(run.id, f"poll:{officers[0].id}:tab1"))
        frames = first.get(f"{url}?viewer=tab1&after=1.0").get_json()["frames"]
        assert [f["step"] for f in frames] == [1100]
        # a relay that fails (here: the run has no constellation to reach) is not restarted
        # at every poll, but after a pause
        with pytest.raises(CloudSimError, match="no longer exists"):
            relay_job(JobContext(relays[0]), RunJob.from_job(relays[0]))
        assert redis_client().get(_key(run.id, "relay")) == "failed"
        redis_client().delete(_key(run.id, f"poll:{officers[0].id}:tab1"))
        assert first.get(f"{url}?viewer=tab1").get_json()["relay"] == "failed"
        assert db.session.scalar(db.select(db.func.count(Job.id))) == 1


def test_the_api_gives_a_script_the_scene_and_the_replay_frames(
    app: Flask, people: dict[str, User | None], run_logs: Path
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    run = store_run(user_a.team, run_logs)
    client, headers = app.test_client(), token_for(user_a)
    scene = client.get(f"/api/v1/runs/{run.id}/view/scene", headers=headers)
    assert scene.status_code == 200 and scene.json["run"]["mode"] == "replay"
    robot = str(scene.json["scene"]["roles"]["robot"])
    frames = client.get(
        f"/api/v1/runs/{run.id}/view/frames",
        query_string={"start": 4, "seconds": 2},
        headers=headers,
    )
    assert frames.status_code == 200 and len(frames.json["frames"]) == 66
    assert len(frames.json["frames"][0]["poses"][robot]) == 7 * 31
    for bad in ({"seconds": 31}, {"start": -1}, {"start": "soon"}):
        answer = client.get(f"/api/v1/runs/{run.id}/view/frames", query_string=bad, headers=headers)
        assert answer.status_code == 400, bad
    other = client.get(f"/api/v1/runs/{run.id}/view/scene", headers=token_for(people["user_b"]))
    assert other.status_code == 404


def test_the_replay_cache_keeps_the_most_recently_viewed_runs_only(
    app: Flask, people: dict[str, User | None], run_logs: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(viewer_service, "CACHED_REPLAYS", 2)
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    first, second, third = (store_run(user_a.team, run_logs) for _ in range(3))
    client = _client(app, user_a)
    cache = app.config["CLOUDSIM"].instance_dir / "viewer"

    def replay(run_id: int) -> None:
        answer = client.get(f"/runs/{run_id}/view/frames?start=0&seconds=0.1")
        assert answer.status_code == 200 and answer.get_json()["frames"], answer.get_data()

    for run in (first, second, third):
        replay(run.id)
    assert {f.name for f in cache.iterdir()} == {f"run-{second.id}", f"run-{third.id}"}
    replay(first.id)  # copied again when asked for
    assert {f.name for f in cache.iterdir()} == {f"run-{first.id}", f"run-{third.id}"}


def test_a_replay_closed_by_another_request_meanwhile_is_opened_again(
    app: Flask, people: dict[str, User | None], run_logs: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(viewer_service, "OPEN_REPLAYS", 1)
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    mine, other = store_run(user_a.team, run_logs), store_run(user_a.team, run_logs)
    other_logs = viewer_service._local_logs(other, app.config["CLOUDSIM"])
    opened = viewer_service._Replays.get
    raced: list[int] = []

    def get_then_evicted(self: Any, run_id: int, folder: Path) -> Any:
        entry = opened(self, run_id, folder)
        if run_id == mine.id and not raced:  # another request opens its run: ours is closed
            raced.append(run_id)
            opened(self, other.id, other_logs)
        return entry

    monkeypatch.setattr(viewer_service._Replays, "get", get_then_evicted)
    answer = _client(app, user_a).get(f"/runs/{mine.id}/view/frames?start=2&seconds=1")
    assert raced and answer.status_code == 200 and len(answer.get_json()["frames"]) == 33


def test_a_run_without_a_state_log_is_refused_and_leaves_no_cache_behind(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team_id is not None
    run = finished_run(open_task(user_a.team_id), None, tmp_path)  # its score log only
    answer = _client(app, user_a).get(f"/runs/{run.id}/view/frames")
    assert answer.status_code == 409 and "no meta.json to replay" in answer.get_data(as_text=True)
    assert not (app.config["CLOUDSIM"].instance_dir / "viewer" / f"run-{run.id}").exists()


def _close_replays() -> None:
    for poses, _ in viewer_service._replays.open.values():
        poses.close()
    viewer_service._replays.open.clear()


@pytest.fixture
def fresh_replays() -> Iterator[None]:
    """Close the replays this process keeps open by run id (each test's runs start at 1)."""
    _close_replays()
    yield
    _close_replays()


@pytest.mark.usefixtures("fresh_replays")
def test_the_scene_and_replay_are_of_the_world_the_run_was_built_from(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    user_a = people["user_a"]
    assert user_a is not None and user_a.team is not None
    world = shipped_document("vrc_task_2")
    world["objects"][0]["pose"] = [4.5, 0.5, 0.0]  # gate_1 moved
    folder = tmp_path / "run"
    sim = Simulation("vrc_task_2", "1", RunOptions(log_dir=folder, world_document=world))
    sim.step(300)
    sim.close()
    run = store_run(user_a.team, folder)
    store_log(run, folder / "world.json", "world.json")
    db.session.commit()
    client = _client(app, user_a)
    scene = client.get(f"/runs/{run.id}/view/scene").get_json()["scene"]
    assert scene["roles"]["gates"]["gate_1"]["x"] == 4.5
    frames = client.get(f"/runs/{run.id}/view/frames?start=0&seconds=0.2").get_json()["frames"]
    assert len(frames) == 6  # every 30 ms up to 0.2 s, from the state log rebuilt on...
    replayed = viewer_service._replays.open[run.id][0]  # ...the world the run was built from
    assert replayed.sim.scene.gates["gate_1"].x == 4.5
    # a live run (no logs kept yet) is drawn from the world this CloudSim holds
    world["objects"][0]["pose"] = [5.5, 0.0, 0.0]
    update_world(SYSTEM, world)
    task = open_task(user_a.team.id)
    live = Run(task_id=task.id, team_id=task.team_id, state=RunState.RUNNING)
    db.session.add(live)
    db.session.commit()
    officer = _client(app, people["officer"])
    scene = officer.get(f"/runs/{live.id}/view/scene").get_json()["scene"]
    assert scene["roles"]["gates"]["gate_1"]["x"] == 5.5
