"""Alembic environment: run migrations on the Flask app's engine."""

from __future__ import annotations

from typing import Any

from alembic import context
from sqlalchemy.types import TypeDecorator

from cloudsim.extensions import db
from cloudsim.models import Base

config = context.config
app = config.attributes.get("flask_app")
if app is None:  # e.g. `alembic` run by hand: build the app from the environment
    from cloudsim.app import create_app

    app = create_app()


def render_item(kind: str, obj: Any, autogen_context: Any) -> str | bool:
    """Write our column types as plain SQL types: migrations must not import app code."""
    if (
        kind == "type"
        and isinstance(obj, TypeDecorator)
        and type(obj).__module__.startswith("cloudsim")
    ):
        return f"sa.{type(obj.impl_instance).__name__}()"
    return False


def run_migrations() -> None:
    """Migrate online, inside the app context, with batch mode for SQLite's ALTER limits."""
    with app.app_context():
        engine = db.engine
        with engine.connect() as connection:
            context.configure(
                connection=connection,
                target_metadata=Base.metadata,
                render_as_batch=engine.dialect.name == "sqlite",
                compare_type=True,
                render_item=render_item,
            )
            with context.begin_transaction():
                context.run_migrations()
            connection.commit()


run_migrations()
