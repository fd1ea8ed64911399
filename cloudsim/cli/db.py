"""`cloudsim db`: schema migrations."""

from __future__ import annotations

import click

from cloudsim import migrate
from cloudsim.cli import app_context, reports_errors


@click.group()
def db() -> None:
    """Migrate the database schema."""


@db.command()
@click.argument("revision", default="head")
@reports_errors
def upgrade(revision: str) -> None:
    """Upgrade the schema to REVISION (default: the newest)."""
    with app_context() as app:
        migrate.upgrade(app, revision)
        click.echo(f"database at revision {migrate.current(app)}")


@db.command()
@click.argument("revision")
@reports_errors
def downgrade(revision: str) -> None:
    """Downgrade the schema to REVISION ("base" removes every table)."""
    with app_context() as app:
        migrate.downgrade(app, revision)
        click.echo(f"database at revision {migrate.current(app) or 'base'}")


@db.command()
@reports_errors
def current() -> None:
    """Print the schema revision of the database."""
    with app_context() as app:
        click.echo(migrate.current(app) or "base (empty database)")
