"""`cloudsim portal`: the master portal's HTTPS certificate, and the uploads it refused."""

from __future__ import annotations

from pathlib import Path

import click
from flask import current_app

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.portal import credentials, review


@click.group()
def portal() -> None:
    """The portal: where team instances upload their runs."""


@portal.command()
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="folder to write portal.crt and portal.key into (0600)",
)
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def certificate(out: Path, as_json: bool) -> None:
    """Write the HTTPS certificate (and key) the master serves its portal with: set them as
    CLOUDSIM_TLS_CERT and CLOUDSIM_TLS_KEY; instances pin its SHA-256."""
    with app_context():
        config = current_app.config["CLOUDSIM"]
        try:
            cert, key, tls = credentials.write_certificate(config, out)
        except ValueError as exc:
            raise InvalidInput(str(exc)) from None
        data = {"cert": str(cert), "key": str(key), "host": tls.host, "sha256": tls.fingerprint}
        emit(data, as_json, f"{cert}\n{key}\nsha256 {tls.fingerprint} (for {tls.host})")


@portal.command()
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def refusals(as_json: bool) -> None:
    """List the results the portal refused, newest first (the last 100)."""
    with app_context():
        rows = list(db.session.scalars(review.refusals(SYSTEM).limit(100)))
        data = [
            {
                "id": r.id,
                "instance": r.instance.name if r.instance else None,
                "remote_run_id": r.remote_run_id,
                "run_id": r.run_id,
                "reason": r.reason,
                "created_at": r.created_at,
            }
            for r in rows
        ]
        lines = [
            f"{r['created_at']:%Y-%m-%d %H:%M:%S}  {r['instance'] or '-'}  run "
            f"{r['remote_run_id'] or '-'}: {r['reason']}"
            for r in data
        ]
        emit(data, as_json, "\n".join(lines) or "no refused uploads")
