"""Alembic migrations match the models and go up and down on SQLite and PostgreSQL."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect

from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Base
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
