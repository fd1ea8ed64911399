"""The `cloudsim` command: start the system and migrate the database; features add the rest."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import wraps
from typing import Any, TypeVar, cast

import click
from flask import Flask

from cloudsim import extensions  # not `db`: that name is the `cloudsim db` submodule
from cloudsim.config import Config, ConfigError
from cloudsim.errors import CloudSimError
from cloudsim.web.inputs import INT32_MAX

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

            self._app = create_app(Config.from_env())
        return self._app


@contextmanager
def app_context() -> Iterator[Flask]:
    """Yield the app inside its context; commit what the block changed (the command's boundary)."""
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
    extensions.db.session.commit()


def reports_errors(fn: F) -> F:
    """Turn CloudSim errors into a one-line message and a non-zero exit code."""

    @wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (CloudSimError, ConfigError) as exc:
            raise click.ClickException(str(exc)) from None

    return cast(F, wrapped)


def emit(data: Any, as_json: bool, text: str) -> None:
    """Print JSON for scripts or a line for people."""
    click.echo(json.dumps(data, indent=2, default=str) if as_json else text)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.pass_context
def main(ctx: click.Context) -> None:
    """CloudSim: cloud-hosted, real-time robot simulation competitions."""
    ctx.obj = AppHolder()


def _register() -> None:
    from cloudsim.cli import db, up, workers
    from cloudsim.features import features

    main.add_command(up.up)
    main.add_command(db.db)
    main.add_command(workers.worker)
    main.add_command(workers.beat)
    for feature in features():
        feature.init_cli(main)


_register()
