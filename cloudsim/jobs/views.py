"""Pages that follow jobs live, and the JSON their pages poll."""

from __future__ import annotations

from flask import Blueprint, flash, jsonify, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.extensions import db
from cloudsim.jobs.service import get_job, queue_depths, start_maintenance, visible_jobs
from cloudsim.models import Job, Role
from cloudsim.web.inputs import query_int

bp = Blueprint("jobs", __name__)
PAGE_SIZE = 50


def job_summary(job: Job, *, with_log: bool = False) -> dict[str, object]:
    """Return the JSON form of a job (used by the page's live updates and by the API)."""
    data: dict[str, object] = {
        "id": job.id,
        "kind": job.kind,
        "state": job.state.value,
        "stage": job.stage,
        "progress": job.progress,
        "error": job.error,
        "target_type": job.target_type,
        "target_id": job.target_id,
        "team_id": job.team_id,
        "attempts": job.attempts,
        "created_at": job.created_at.isoformat(),
        "started_at": job.started_at.isoformat() if job.started_at else None,
        "finished_at": job.finished_at.isoformat() if job.finished_at else None,
    }
    if with_log:
        data["log"] = job.log
    return data


@bp.route("/jobs")
@role_required(Role.OFFICER)
def index() -> ResponseReturnValue:
    page = query_int("page", 1, minimum=1)
    state = request.args.get("state") or None
    query = visible_jobs(current_user, state=state)
    jobs = db.paginate(query, page=page, per_page=PAGE_SIZE, error_out=False)
    return render_template(
        "jobs/index.html",
        jobs=jobs,
        state=state,
        queues=queue_depths(current_user),
        confirm=ConfirmForm(),
    )


@bp.route("/jobs/diagnostics", methods=["POST"])
@role_required(Role.ADMIN)
def start_diagnostics() -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("jobs.index")), 400
    job = start_maintenance("diagnostics", current_user)
    flash("Diagnostics started.", "info")
    return redirect(url_for("jobs.show", job_id=job.id))


@bp.route("/jobs/<job_id>")
@role_required(Role.OFFICER)
def show(job_id: str) -> ResponseReturnValue:
    return render_template("jobs/show.html", job=get_job(current_user, job_id))


@bp.route("/jobs/<job_id>/progress")
@role_required(Role.OFFICER)
def progress(job_id: str) -> ResponseReturnValue:
    """Return the job's state and the part of its log after `since` characters."""
    job = get_job(current_user, job_id)
    since = query_int("since", 0)
    data = job_summary(job)
    data["log"] = (job.log or "")[since:]
    data["log_length"] = len(job.log or "")
    return jsonify(data)
