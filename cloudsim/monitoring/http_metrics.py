"""HTTP request durations by route, the one metric counted in the web processes themselves.

gunicorn runs several worker processes: under `cloudsim up` each writes its counts to files
in PROMETHEUS_MULTIPROC_DIR (prometheus_client's multiprocess mode) and /metrics sums them;
a single process (a test, `flask run`) serves its own counts.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

from flask import Flask, Response, g, request
from prometheus_client import Histogram
from prometheus_client.core import Metric
from prometheus_client.registry import Collector

BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)
_histogram: Histogram | None = None


def request_seconds() -> Histogram:
    """Return the process's histogram, made on first use (after PROMETHEUS_MULTIPROC_DIR is
    read: prometheus_client picks file-backed values only if it is set by then)."""
    global _histogram
    if _histogram is None:
        _histogram = Histogram(
            "cloudsim_http_request_duration_seconds",
            "Time to answer an HTTP request, by route, method and status",
            ["route", "method", "status"],
            buckets=BUCKETS,
            registry=None,  # collected by /metrics, never by a global registry
        )
    return _histogram


class ThisProcess(Collector):
    """Collect this process's request timings."""

    def collect(self) -> Iterator[Metric]:
        yield from request_seconds().collect()


def init_http_metrics(app: Flask) -> None:
    """Time every request by its route's rule (never its concrete path: bounded labels)."""
    histogram = request_seconds()

    def start_clock() -> None:
        g.metrics_started = time.perf_counter()

    # first of all, so the time of every other hook counts (and refused requests are timed)
    app.before_request_funcs.setdefault(None, []).insert(0, start_clock)

    @app.after_request
    def observe(response: Response) -> Response:
        started = g.pop("metrics_started", None)
        if started is not None:
            route = request.url_rule.rule if request.url_rule is not None else "unmatched"
            histogram.labels(route, request.method, str(response.status_code)).observe(
                time.perf_counter() - started
            )
        return response
