"""Monitoring: health and readiness, Prometheus metrics, worker and beat heartbeats, JSON logs
(see docs/monitoring.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register the health, readiness and metrics routes, the request ids and timings."""
    from cloudsim.monitoring import heartbeats, views  # noqa: F401 (signal receivers)
    from cloudsim.monitoring.http_metrics import init_http_metrics
    from cloudsim.monitoring.logs import init_request_logs, use_json_logs

    config = app.config["CLOUDSIM"]
    if config.log_format == "json":
        use_json_logs(config.log_level)
        _celery_keeps_json_logs()
    app.register_blueprint(views.bp)
    init_request_logs(app)
    init_http_metrics(app)


def _celery_keeps_json_logs() -> None:
    """Stop a worker or the beat from replacing the JSON handler with its own format."""
    from celery.signals import setup_logging

    # With a receiver connected, Celery leaves logging as the app set it up.
    setup_logging.connect(_keep_logging, weak=False)


def _keep_logging(**_: Any) -> None:
    """Leave logging as configured (a `setup_logging` receiver)."""


def init_cli(cli: LazyGroup) -> None:
    """Add `cloudsim status`."""
    cli.add_lazy_command(
        "status",
        "cloudsim.monitoring.cli:status",
        "Check the database, Redis, workers, beat, disk and outbox; exit 1 when one fails.",
    )
