"""Alembic migrations match the models and go up and down on SQLite and PostgreSQL."""

from __future__ import annotations

import copy
from collections.abc import Callable
from datetime import timedelta

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from drcsim.worlds import document_digest, shipped_document
from sqlalchemy import insert, inspect, select

from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Base, Run, RunState, Task, World, utcnow
from cloudsim.people.service import create_team
from tests.support.servers import PostgresServer


@pytest.mark.parametrize("backend", ["sqlite", "postgres"])
def test_upgrade_matches_models_and_downgrade_removes_everything(
    backend: str, make_config: Callable[..., Config], request: pytest.FixtureRequest
) -> None:
    url = None
    if backend == "postgres":
        server: PostgresServer = request.getfixturevalue("postgres_server")
        url = server.create_database(f"migrations_{id(request)}")
    app = create_app(make_config(url))
    migrate.upgrade(app)
    with app.app_context():
        assert migrate.current(app) is not None
        with db.engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        assert diff == [], f"models and migrations differ: {diff}"
    migrate.downgrade(app, "base")
    with app.app_context():
        tables = set(inspect(db.engine).get_table_names()) - {"alembic_version"}
        assert tables == set()
        assert migrate.current(app) is None
    migrate.upgrade(app)  # and back up again, as after a rollback of a release
    with app.app_context():
        assert "users" in inspect(db.engine).get_table_names()
        db.engine.dispose()


def test_0012_ends_a_second_live_run_of_a_task_with_the_reason(
    make_config: Callable[..., Config],
) -> None:
    app = create_app(make_config())
    migrate.upgrade(app, "0011")
    with app.app_context():
        team = create_team(SYSTEM, "Team A")
        counted, raced = _old_task(team.id), _old_task(team.id)
        rows = {
            "finished": (counted, RunState.FINISHED),
            "live after finished": (counted, RunState.RUNNING),
            "first live": (raced, RunState.RUNNING),
            "second live": (raced, RunState.STARTING),
        }
        # the table as 0011 has it: only the columns named here (and those with defaults)
        ids = {
            name: db.session.scalar(
                insert(Run.__table__)
                .values(task_id=task_id, team_id=team.id, state=state.value)
                .returning(Run.__table__.c.id)
            )
            for name, (task_id, state) in rows.items()
        }
        db.session.commit()
        db.session.remove()
    migrate.upgrade(app)
    with app.app_context():
        states = {name: db.session.get(Run, run_id) for name, run_id in ids.items()}
        assert {name: run.state for name, run in states.items() if run} == {
            "finished": RunState.FINISHED,
            "live after finished": RunState.ERROR,
            "first live": RunState.RUNNING,
            "second live": RunState.ERROR,
        }
        assert "second live run of its task" in (states["second live"].error or "")
        db.engine.dispose()


def _old_task(team_id: int) -> int:
    """Add an open task with only the columns 0011's table has; return its id."""
    now = utcnow()
    return db.session.scalar(  # type: ignore[return-value]
        insert(Task.__table__)
        .values(
            team_id=team_id,
            name="Task",
            world="vrc_task_2",
            run_config=1,
            window_start=now - timedelta(minutes=1),
            window_stop=now + timedelta(minutes=30),
            timeout_s=1800,
            latency_ms=250,
            uplink_bits=1_000_000,
            downlink_bits=8_000_000,
            order=0,
            time_zone="UTC",
            created_at=now,
        )
        .returning(Task.__table__.c.id)
    )


def _stored_world_becomes_shipped(
    make_config: Callable[..., Config], revision: str, old: dict, what: str, version: int = 2
) -> None:
    """Store `old` as vrc_task_2 at `revision`, upgrade: it is the shipped world, `version`."""
    shipped = shipped_document("vrc_task_2")
    assert old != shipped
    app = create_app(make_config())
    migrate.upgrade(app, revision)
    with app.app_context():
        world = db.session.scalars(select(World).where(World.name == "vrc_task_2")).one()
        world.document, world.digest = old, document_digest(old)
        db.session.commit()
        db.session.remove()
    migrate.upgrade(app)
    with app.app_context():
        world = db.session.scalars(select(World).where(World.name == "vrc_task_2")).one()
        assert world.document == shipped and world.version == version
        assert world.digest == document_digest(shipped)
        others = db.session.scalars(select(World).where(World.name != "vrc_task_2")).all()
        assert {w.version for w in others} == {1}, f"no {what}: untouched"
        db.engine.dispose()


def test_0013_gives_stored_worlds_with_the_old_soft_mud_the_shipped_mud(
    make_config: Callable[..., Config],
) -> None:
    old = copy.deepcopy(shipped_document("vrc_task_2"))
    configs = old["configs"].values()
    for patch in [old["terrain"][0], *(c.get("terrain", {}).get("mud", {}) for c in configs)]:
        patch.pop("depth", None)
        if "friction" in patch:
            patch.update(friction=0.3, stiffness=20000.0)
    assert old["terrain"][0]["kind"] == "mud"
    _stored_world_becomes_shipped(make_config, "0012", old, "mud")


def test_a_world_stored_before_0013_reaches_the_shipped_world(
    make_config: Callable[..., Config],
) -> None:
    # as 0012 held it: the soft-slab mud and every patch's walk_speed (0013, then 0014)
    old = copy.deepcopy(shipped_document("vrc_task_2"))
    for patch in old["terrain"]:
        patch["walk_speed"] = 0.5
        if patch["kind"] == "mud":
            patch.pop("depth")
            patch.update(stiffness=40000.0, damping=2000.0)
    old["configs"]["5"]["terrain"]["mud"] = {"friction": 0.2, "stiffness": 10000.0}
    _stored_world_becomes_shipped(make_config, "0012", old, "change", version=3)


def test_0014_takes_walk_speed_out_of_stored_worlds(make_config: Callable[..., Config]) -> None:
    old = copy.deepcopy(shipped_document("vrc_task_2"))
    old["terrain"][0]["walk_speed"] = 0.45
    old["configs"]["3"]["terrain"]["rubble"]["walk_speed"] = 0.55
    _stored_world_becomes_shipped(make_config, "0013", old, "walk_speed")
