"""The diagnostics job: checks, from a worker, everything a job depends on."""

from __future__ import annotations

import shutil

from flask import current_app
from sqlalchemy import text

from cloudsim.crypto import keyring
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind

MIN_FREE_BYTES = 1 << 30


@job_kind("diagnostics", maintenance=True)
def run_diagnostics(ctx: JobContext, _: Payload) -> None:
    """Check the database, the queue, the keyring and the instance folder's free space."""
    settings = current_app.config["CLOUDSIM"]
    ctx.stage("database", 10)
    db.session.execute(text("SELECT 1"))
    ctx.log(f"database reachable ({db.engine.dialect.name})")
    ctx.stage("queue", 35)
    celery = current_app.extensions["celery"]
    with celery.connection_for_write() as conn:
        conn.ensure_connection(max_retries=1)
    ctx.log("job queue reachable")
    ctx.stage("keyring", 60)
    probe = "diagnostics-probe"
    if keyring().decrypt(keyring().encrypt(probe)) != probe:
        raise CloudSimError("the encryption keyring does not round-trip")
    ctx.log("encryption keys usable")
    ctx.stage("disk", 85)
    free = shutil.disk_usage(settings.instance_dir).free
    ctx.log(f"{free / 2**30:.1f} GiB free in the instance folder")
    if free < MIN_FREE_BYTES:
        raise CloudSimError(f"less than 1 GiB free in {settings.instance_dir}")
