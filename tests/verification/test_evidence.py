"""What holds a run before or by its replay: a missing log, a log changed in the store, logs of
another task, a world this CloudSim holds differently (the job run in this process)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from drcsim.rundir import COMMANDS, FINAL
from drcsim.worlds import shipped_document
from flask import Flask, current_app
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.extensions import db
from cloudsim.jobs.service import run_here
from cloudsim.models import Job, JobState, Role, Run, Task, Verification
from cloudsim.people.service import create_team
from cloudsim.verification import service
from cloudsim.worlds.service import update_world
from tests.competition.support import open_task
from tests.conftest import log_in, make_user
from tests.verification.support import TIMEOUT_S, WORLD_NAME, master_run, simulate


@pytest.fixture(scope="module")
def real_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    return simulate(tmp_path_factory.mktemp("run"), shipped_document(WORLD_NAME))


def _verify(run: Run) -> Run:
    assert service.request_verification(run.id)
    db.session.commit()
    job = db.session.scalar(select(Job).where(Job.kind == service.VERIFY, Job.target_id == run.id))
    assert job is not None
    run_here(job.id)
    db.session.expire_all()
    assert db.session.get(Job, job.id).state == JobState.SUCCEEDED  # type: ignore[union-attr]
    assert not (current_app.config["CLOUDSIM"].instance_dir / "verification" / str(run.id)).exists()
    return run


def _task(**fields: object) -> Task:
    return open_task(create_team(SYSTEM, "Team A").id, **fields)


def _change_stored(run: Run, filename: str) -> None:
    store = LogStore(current_app.config["CLOUDSIM"])
    artifact = artifact_for(run, filename)
    assert artifact is not None
    folder = Path(store.driver.get_container_cdn_url(store.container, check=True))
    stored = folder / artifact.location
    stored.write_bytes(stored.read_bytes().replace(b'"r_arm_shz": 0.4}', b'"r_arm_shz": 0.5}'))


CASES: dict[str, tuple[Callable[[dict[str, bytes]], dict[str, bytes]], dict[str, object], str]] = {
    "no final record": (
        lambda logs: {k: v for k, v in logs.items() if k != FINAL},
        {},
        "the run has no final.json: it cannot be re-simulated",
    ),
    "logs of another timeout": (
        lambda logs: logs,
        {"timeout_s": 90},
        "the logs are of vrc_task_2 #1 with a 60.0 s limit; the task is vrc_task_2 #1 with 90 s",
    ),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_a_run_whose_logs_cannot_prove_it_is_held(
    app: Flask, real_logs: dict[str, bytes], tmp_path: Path, case: str
) -> None:
    change, task_fields, reason = CASES[case]
    task = _task(**{"timeout_s": TIMEOUT_S, **task_fields})
    run = _verify(master_run(task, change(real_logs), tmp_path))
    assert run.verification == Verification.HELD
    assert run.verification_reason == reason


def test_a_log_changed_in_the_store_holds_its_run(
    app: Flask, real_logs: dict[str, bytes], tmp_path: Path
) -> None:
    run = master_run(_task(timeout_s=TIMEOUT_S), real_logs, tmp_path)
    _change_stored(run, COMMANDS)
    run = _verify(run)
    assert run.verification == Verification.HELD
    assert (run.verification_reason or "").startswith(
        "commands.jsonl in the log store is not the log that was stored"
    )


def test_a_run_is_replayed_in_the_world_this_cloudsim_holds(
    app: Flask, real_logs: dict[str, bytes], tmp_path: Path
) -> None:
    run = master_run(_task(timeout_s=TIMEOUT_S), real_logs, tmp_path)
    world = shipped_document(WORLD_NAME)
    next(o for o in world["objects"] if o["id"] == "gate_1")["pose"] = [1.5, 0.0, 0.0]
    update_world(SYSTEM, world)  # after the run: the run's world is no longer the one held
    run = _verify(run)
    assert run.verification == Verification.HELD
    assert run.verification_reason == (
        "the replay of its command log diverged: the world document differs from the one the "
        "run was built from"
    )


def test_the_jobs_page_shows_the_verification_queue(
    app: Flask, real_logs: dict[str, bytes], tmp_path: Path
) -> None:
    team = create_team(SYSTEM, "Team A")
    for n in range(2):
        task = open_task(team.id, timeout_s=TIMEOUT_S, name=f"Walking {n}")
        master_run(task, real_logs, tmp_path / str(n))
    assert service.sweep() == 2
    db.session.commit()  # queued; no worker here takes them
    client = app.test_client()
    log_in(client, make_user(Role.OFFICER))
    page = client.get("/jobs").get_data(as_text=True)
    row = page[page.index('data-kind="run.verify"') :].split("</tr>")[0]
    assert '<td class="queued">2</td>' in row and '<td class="running">0</td>' in row
