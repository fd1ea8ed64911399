"""The `cloudsim` command: start the system and migrate the database; features add the rest."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import wraps
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click

from cloudsim import __version__
from cloudsim.cli.lazy import LazyGroup
from cloudsim.errors import CloudSimError
from cloudsim.limits import INT32_MAX

if TYPE_CHECKING:
    import sqlalchemy.exc
    from flask import Flask

# Flask, the models and the config load when a command runs, never for `cloudsim --help`.

F = TypeVar("F", bound=Callable[..., Any])
# A row's id as a command's argument: one the database can hold, else click's usage error.
ID = click.IntRange(1, INT32_MAX)


class AppHolder:
    """Build the app once, on first use, so `cloudsim --help` needs no database."""

    def __init__(self) -> None:
        self._app: Flask | None = None

    def get(self) -> Flask:
        if self._app is None:
            from cloudsim.app import create_app
            from cloudsim.config import Config

            self._app = create_app(Config.from_env())
        return self._app


@contextmanager
def app_context() -> Iterator[Flask]:
    """Yield the app inside its context; commit what the block changed (the command's boundary)."""
    from cloudsim import extensions  # not `db`: that name is the `cloudsim db` submodule

    holder = click.get_current_context().find_object(AppHolder)
    assert holder is not None
    app = holder.get()
    with app.app_context():
        try:
            yield app
        except BaseException:
            extensions.db.session.rollback()
            raise
        extensions.db.session.commit()


def commit() -> None:
    """Commit the command's work now, before it only waits and reads (its jobs start here)."""
    from cloudsim import extensions

    extensions.db.session.commit()


def reports_errors(fn: F) -> F:
    """Turn CloudSim errors into a one-line message and a non-zero exit code."""

    @wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        from sqlalchemy.exc import OperationalError

        from cloudsim.config import ConfigError

        try:
            for name, value in kwargs.items():
                _check_text(name, value)
            return fn(*args, **kwargs)
        except (CloudSimError, ConfigError) as exc:
            raise click.ClickException(str(exc)) from None
        except OperationalError as exc:
            # e.g. "no such table" before `cloudsim db upgrade` made the schema
            raise click.ClickException(_database_problem(exc)) from None

    return cast(F, wrapped)


def _check_text(name: str, value: Any) -> None:
    """Refuse an argument that is not UTF-8 (click keeps such bytes as lone surrogates)."""
    values = value if isinstance(value, tuple | list) else (value,)
    for item in values:
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                option = name.replace("_", "-").upper()
                raise click.ClickException(f"{option} is not UTF-8 text") from None


def _database_problem(exc: sqlalchemy.exc.OperationalError) -> str:
    text = str(exc.orig).splitlines()[0] if exc.orig is not None else str(exc).splitlines()[0]
    if "no such table" in text or "does not exist" in text:
        return f"the database has no CloudSim tables yet ({text}): run `cloudsim db upgrade`"
    return f"database error: {text}"


def emit(data: Any, as_json: bool, text: str) -> None:
    """Print JSON for scripts or a line for people."""
    click.echo(json.dumps(data, indent=2, default=str) if as_json else text)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, message="cloudsim %(version)s")
@click.pass_context
def main(ctx: click.Context) -> None:
    """CloudSim: cloud-hosted, real-time robot simulation competitions."""
    ctx.obj = AppHolder()


def _register() -> None:
    from cloudsim.features import features

    main.add_lazy_command(
        "up",
        "cloudsim.cli.up:up",
        "Run CloudSim on this machine until Ctrl-C: Redis (if needed), workers, beat, web.",
    )
    main.add_lazy_command("db", "cloudsim.cli.db:db", "Migrate the database schema.")
    main.add_lazy_command(
        "worker",
        "cloudsim.cli.workers:worker",
        "Run only a Celery worker (no web server, beat or Redis) against CLOUDSIM_* settings.",
    )
    main.add_lazy_command(
        "beat",
        "cloudsim.cli.workers:beat",
        "Run only the beat (one per system) against CLOUDSIM_* settings.",
    )
    for feature in features():
        feature.init_cli(main)


_register()
