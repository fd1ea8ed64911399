"""`cloudsim notify`: send again the run notices the queue missed."""

from __future__ import annotations

import click

from cloudsim.cli import app_context, reports_errors


@click.group()
def notify() -> None:
    """Run notifications: send again what the queue missed."""


@notify.command("resend")
@reports_errors
def resend() -> None:
    """Queue again every e-mail and webhook delivery not done yet, within its tries."""
    from cloudsim.notifications.delivery import resend_pending

    with app_context():
        queued = resend_pending()
    click.echo(f"{queued} queued")
