"""GET /healthz, /readyz (for load balancers and systemd) and /metrics (for Prometheus)."""

from __future__ import annotations

import hmac
import ipaddress
import os

from flask import Blueprint, Response, abort, current_app, request
from flask.typing import ResponseReturnValue
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
from prometheus_client.multiprocess import MultiProcessCollector

from cloudsim.config import Config
from cloudsim.monitoring import http_metrics
from cloudsim.monitoring.collector import CloudSimCollector
from cloudsim.monitoring.health import readiness

bp = Blueprint("monitoring", __name__)


@bp.get("/healthz")
def healthz() -> ResponseReturnValue:
    """Answer that this process serves requests (nothing else is checked)."""
    return {"status": "alive"}


@bp.get("/readyz")
def readyz() -> ResponseReturnValue:
    """Check every part CloudSim needs; 503 naming the failing ones when one is down."""
    ready, body = readiness()
    return body, 200 if ready else 503


def _allowed(config: Config) -> bool:
    """Whether the caller comes from a configured network or shows the metrics token."""
    given = request.headers.get("Authorization", "")
    if config.metrics_token and hmac.compare_digest(
        given.encode(), f"Bearer {config.metrics_token}".encode()
    ):
        return True
    try:
        address = ipaddress.ip_address(request.remote_addr or "")
    except ValueError:
        return False
    return any(address in ipaddress.ip_network(net) for net in config.metrics_networks)


@bp.get("/metrics")
def metrics() -> ResponseReturnValue:
    """Serve CloudSim's metrics in Prometheus' text format (configured networks or token)."""
    if not _allowed(current_app.config["CLOUDSIM"]):
        abort(403)
    registry = CollectorRegistry(auto_describe=False)
    registry.register(CloudSimCollector(current_app._get_current_object()))  # type: ignore[attr-defined]
    if os.environ.get("PROMETHEUS_MULTIPROC_DIR"):
        MultiProcessCollector(registry)  # every gunicorn worker's request timings
    else:
        registry.register(http_metrics.ThisProcess())
    return Response(generate_latest(registry), mimetype=CONTENT_TYPE_LATEST)
