"""Celery, bound to the Flask app: every task runs inside the app context."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from celery import Celery, Task
from flask import Flask

from cloudsim.config import Config


def celery_init_app(app: Flask, config: Config) -> Celery:
    """Create the Celery app for this Flask app and make it the default for shared tasks."""

    class FlaskTask(Task):  # type: ignore[misc]
        def __call__(self, *args: Any, **kwargs: Any) -> Any:
            with app.app_context():
                return self.run(*args, **kwargs)

    celery = Celery(app.name, task_cls=FlaskTask)
    redis_url = config.effective_redis_url
    celery.conf.update(
        broker_url=redis_url,
        task_ignore_result=True,
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,
        worker_hijack_root_logger=False,
        broker_connection_retry_on_startup=True,
        broker_transport_options={
            "visibility_timeout": config.job_visibility_timeout,
            "unacked_restore_interval": 5,
        },
        task_default_queue="cloudsim",
        beat_schedule={
            "sweep-jobs": {
                "task": "cloudsim.jobs.sweep",
                "schedule": timedelta(seconds=max(5, config.job_lease_seconds // 2)),
            },
            "reconcile-providers": {
                "task": "cloudsim.fleet.reconcile",
                "schedule": timedelta(minutes=5),
            },
            "supervise-runs": {
                "task": "cloudsim.competition.supervise",
                "schedule": timedelta(seconds=config.run_supervise_seconds),
            },
        },
        timezone="UTC",
    )
    celery.set_default()
    app.extensions["celery"] = celery
    # Importing the task modules registers them with the app's Celery.
    from cloudsim.competition import demo  # noqa: F401
    from cloudsim.competition import engine as competition_engine  # noqa: F401
    from cloudsim.fleet import engine, reconcile  # noqa: F401
    from cloudsim.jobs import diagnostics, runner, service  # noqa: F401

    return celery
