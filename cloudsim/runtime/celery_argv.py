"""The command lines of CloudSim's Celery worker and beat (`cloudsim up`, `cloudsim worker`,
`cloudsim beat` run the same ones)."""

from __future__ import annotations

import sys

from cloudsim.config import Config

QUEUE = "cloudsim"


def _celery(config: Config) -> list[str]:
    quiet = ["--quiet"] if config.log_format == "json" else []  # Celery's banner is no JSON line
    return [sys.executable, "-m", "celery", "-A", "cloudsim.worker", *quiet]


def worker_argv(config: Config) -> list[str]:
    """Return the argv of a worker named after its machine (cloudsim@HOST)."""
    return [
        *_celery(config),
        "worker",
        "--loglevel",
        config.log_level,
        "--concurrency",
        str(config.worker_concurrency),
        "--queues",
        QUEUE,
        "--hostname",
        "cloudsim@%h",
    ]


def beat_argv(config: Config) -> list[str]:
    """Return the argv of the beat, its schedule state in the instance folder."""
    return [
        *_celery(config),
        "beat",
        "--loglevel",
        config.log_level,
        "--schedule",
        str(config.instance_dir / "celerybeat-schedule"),
    ]
