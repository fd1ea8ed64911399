"""`cloudsim worker` and `cloudsim beat`: only a worker, or only the beat, for more machines.

They run against the database, Redis and log store the environment names (the master's), so
a second machine adds workers by running `cloudsim worker` with the master's settings.
"""

from __future__ import annotations

import os

import click

from cloudsim.cli import reports_errors
from cloudsim.config import Config
from cloudsim.runtime.celery_argv import beat_argv, worker_argv


def _exec(argv: list[str], config: Config) -> None:
    """Become the Celery process (its signals, its exit code) with the resolved settings."""
    if config.redis_url is None:
        raise click.ClickException(
            "set CLOUDSIM_REDIS_URL to the master's Redis: a worker or beat alone starts none"
        )
    env = dict(os.environ, CLOUDSIM_INSTANCE_DIR=str(config.instance_dir))
    os.execve(argv[0], argv, env)  # noqa: S606 (argv is ours, never a user's)


@click.command()
@reports_errors
def worker() -> None:
    """Run only a Celery worker (no web server, beat or Redis) against CLOUDSIM_* settings."""
    config = Config.from_env()
    _exec(worker_argv(config), config)


@click.command()
@reports_errors
def beat() -> None:
    """Run only the beat (one per system) against CLOUDSIM_* settings."""
    config = Config.from_env()
    _exec(beat_argv(config), config)
