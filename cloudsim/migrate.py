"""Database migrations (Alembic, the `migrations` package's scripts) applied from the app."""

from __future__ import annotations

from alembic import command
from alembic.config import Config as AlembicConfig
from flask import Flask

import migrations


def alembic_config(app: Flask) -> AlembicConfig:
    """Return an Alembic configuration bound to the app's database."""
    config = AlembicConfig()
    config.set_main_option("script_location", str(migrations.folder()))
    config.attributes["flask_app"] = app
    return config


def upgrade(app: Flask, revision: str = "head") -> None:
    """Bring the database schema up to `revision`."""
    with app.app_context():
        command.upgrade(alembic_config(app), revision)


def downgrade(app: Flask, revision: str) -> None:
    """Take the database schema back to `revision` ("base" removes everything)."""
    with app.app_context():
        command.downgrade(alembic_config(app), revision)


def current(app: Flask) -> str | None:
    """Return the database's current revision, or None for an empty database."""
    from alembic.runtime.migration import MigrationContext

    with app.app_context():
        from cloudsim.extensions import db

        with db.engine.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()
