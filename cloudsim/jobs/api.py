"""Background jobs."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView

from cloudsim.api.common import Blueprint, SelectPage, caller, caller_with
from cloudsim.jobs.schemas import JobDetailSchema, JobQuerySchema, JobSchema
from cloudsim.jobs.service import get_job, start_maintenance, visible_jobs
from cloudsim.models import Role

blp = Blueprint("api_jobs", __name__, description="Background jobs and their progress")


@blp.route("/jobs")
class Jobs(MethodView):
    @blp.arguments(JobQuerySchema, location="query")
    @blp.response(200, JobSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self, query: dict[str, Any]) -> Any:
        """List jobs, newest first (officers and admins)."""
        return visible_jobs(caller_with(Role.OFFICER, "list jobs"), state=query.get("state"))

    @blp.arguments(JobSchema)
    @blp.response(202, JobSchema)
    def post(self, data: dict[str, Any]) -> Any:
        """Start a maintenance job such as `diagnostics` (admins)."""
        return start_maintenance(data["kind"], caller())


@blp.route("/jobs/<job_id>")
class JobById(MethodView):
    @blp.response(200, JobDetailSchema)
    def get(self, job_id: str) -> Any:
        """Return a job with its log."""
        return get_job(caller_with(Role.OFFICER, "see jobs"), job_id)
