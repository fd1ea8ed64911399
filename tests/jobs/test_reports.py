"""A job's reports are seen while it runs, without committing the body's changes with them."""

from __future__ import annotations

import pytest
from flask import Flask
from sqlalchemy import create_engine, select

from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext
from cloudsim.models import Job, JobState, Team


@pytest.mark.postgres
def test_a_report_made_after_the_body_wrote_never_commits_the_body(any_db_app: Flask) -> None:
    job = Job(id="reports-1", kind="diagnostics", state=JobState.RUNNING, params={})
    db.session.add(job)
    db.session.commit()
    other = create_engine(db.engine.url.render_as_string(hide_password=False))  # the job page

    def seen() -> tuple[str | None, bool]:
        with other.connect() as conn:
            stage = conn.scalar(select(Job.stage).where(Job.id == job.id))
            team = conn.scalar(select(Team.id).where(Team.name == "Half made"))
        return stage, team is not None

    try:
        before, _ = seen()
        ctx = JobContext(job)
        db.session.add(Team(name="Half made"))
        db.session.flush()  # the body has written: on SQLite it holds the only write lock
        ctx.stage("making things", 40)
        # PostgreSQL shows the report at once; SQLite keeps it for the body's next commit (a
        # second writer would wait for the body's lock); neither commits the body's team.
        live = db.engine.dialect.name != "sqlite"
        assert seen() == ("making things" if live else before, False)
        ctx.checkpoint()
        assert seen() == ("making things", True)
        log = db.session.scalar(select(Job.log).where(Job.id == job.id))
        assert log is not None and log.count("== making things") == 1
    finally:
        other.dispose()
