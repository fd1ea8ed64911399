"""`cloudsim status`: the readiness checks of GET /readyz, on the command line."""

from __future__ import annotations

import sys
import time

import click

from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.extensions import db
from cloudsim.monitoring.health import readiness

POLL_SECONDS = 2.0


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print the /readyz JSON instead.")
@click.option(
    "--wait",
    type=click.IntRange(0, 3600),
    default=0,
    show_default=True,
    help="Keep checking up to this many seconds until ready (systemd's start-up check).",
)
@reports_errors
def status(as_json: bool, wait: int) -> None:
    """Check the database, Redis, workers, beat, disk and outbox; exit 1 when one fails."""
    deadline = time.monotonic() + wait
    with app_context():
        ready, body = readiness()
        while not ready and time.monotonic() < deadline:
            db.session.rollback()  # see what changed meanwhile
            time.sleep(POLL_SECONDS)
            ready, body = readiness()
    lines = [f"CloudSim is {body['status']}"]
    for name, check in body["checks"].items():
        lines.append(f"  {'ok  ' if check['ok'] else 'FAIL'} {name}: {check['detail']}")
    emit(body, as_json, "\n".join(lines))
    if not ready:
        sys.exit(1)
