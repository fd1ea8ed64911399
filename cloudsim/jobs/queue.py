"""Celery, bound to the Flask app: every task runs inside the app context."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from celery import Celery, Task
from flask import Flask

from cloudsim.config import Config
from cloudsim.extensions import db


def celery_init_app(app: Flask, config: Config) -> Celery:
    """Create the Celery app for this Flask app and make it the default for shared tasks."""

    class FlaskTask(Task):  # type: ignore[misc]
        def __call__(self, *args: Any, **kwargs: Any) -> Any:
            # A task is a transaction boundary: it commits once, when it returns.
            with app.app_context():
                try:
                    result = self.run(*args, **kwargs)
                except BaseException:
                    db.session.rollback()
                    raise
                db.session.commit()
                return result

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
        timezone="UTC",
    )
    celery.set_default()
    app.extensions["celery"] = celery
    return celery


def schedule_task(app: Flask, task: str, every: timedelta) -> None:
    """Have Celery beat send `task` periodically."""
    celery: Celery = app.extensions["celery"]
    # A new dict: Celery's default schedule object may be shared between apps. A message not
    # started within one period is dropped: the next one is on its way, so busy workers never
    # work through a backlog of the same periodic task.
    celery.conf.beat_schedule = {
        **celery.conf.beat_schedule,
        task: {"task": task, "schedule": every, "options": {"expires": every.total_seconds()}},
    }
