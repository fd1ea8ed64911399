"""The portal's API: team instances upload runs and logs (with their upload token), officers
see refusals and review runs (with their own API token)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from flask import current_app, g, request
from flask.typing import ResponseReturnValue
from flask.views import MethodView

from cloudsim.api import bearer_token, unauthenticated
from cloudsim.api.common import Blueprint, SelectPage, caller
from cloudsim.competition.api import RunSchema
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.models import TeamInstance
from cloudsim.portal import ingest, review, staging
from cloudsim.portal.credentials import instance_for_token
from cloudsim.portal.schemas import (
    LogStatusSchema,
    OffsetSchema,
    RefusalSchema,
    ReviewSchema,
    RunRecordSchema,
    UploadStatusSchema,
)

INGEST_PREFIX = "/portal/ingest/"
CHUNK_LIMIT = 64 * 1024 * 1024  # the largest piece of a log one request may carry
UPLOAD_SECURITY: list[dict[str, list[str]]] = [{"uploadToken": []}]
T = TypeVar("T")

ingest_blp = Blueprint(
    "api_portal_ingest",
    __name__,
    description="Uploads from team instances to their master's portal (an instance's upload "
    "token: it adds its own team's results only)",
)
blp = Blueprint("api_portal", __name__, description="The portal: refused uploads, run reviews")


@ingest_blp.before_request
def authenticate_instance() -> ResponseReturnValue | None:
    instance = instance_for_token(bearer_token())
    if instance is None:
        return unauthenticated("an instance's upload token is required: 'Bearer cspu_...'")
    g.portal_instance = instance
    return None


def _instance() -> TeamInstance:
    return g.portal_instance  # type: ignore[no-any-return]


def _recording(remote_id: int, action: Callable[[], T]) -> T:
    """Run an ingest step; a refusal is recorded (committed on its own) and then answered."""
    try:
        return action()
    except ingest.Refused as refused:
        db.session.rollback()
        review.record_refusal(_instance(), remote_id, refused)
        db.session.commit()
        if refused.run_id is not None and not isinstance(refused, ingest.ChecksumMismatch):
            # refused for good (the instance stops sending): the run's parts of logs go now
            staging.discard_run(current_app.config["CLOUDSIM"], refused.run_id)
        raise


@ingest_blp.route("/portal/ingest/runs/<int:remote_run_id>")
class UploadedRun(MethodView):
    @ingest_blp.doc(security=UPLOAD_SECURITY)
    @ingest_blp.arguments(RunRecordSchema)
    @ingest_blp.response(200, UploadStatusSchema)
    def put(self, record: dict[str, Any], remote_run_id: int) -> Any:
        """Send a finished run (the instance's run id in the path); answers the master's run
        and how much of each log it has. Sending it again returns the same run."""
        run = _recording(
            remote_run_id, lambda: ingest.receive_run(_instance(), remote_run_id, record)
        )
        return ingest.run_status(run)

    @ingest_blp.doc(security=UPLOAD_SECURITY)
    @ingest_blp.response(200, UploadStatusSchema)
    def get(self, remote_run_id: int) -> Any:
        """How much of an uploaded run's logs the master has (404: the run was not received)."""
        run = ingest.uploaded_run(_instance(), remote_run_id)
        if run is None:
            raise NotFound.of("uploaded run", remote_run_id)
        return ingest.run_status(run)


@ingest_blp.route("/portal/ingest/runs/<int:remote_run_id>/logs/<string:filename>")
class UploadedLog(MethodView):
    @ingest_blp.doc(
        security=UPLOAD_SECURITY,
        requestBody={
            "required": True,
            "content": {
                "application/octet-stream": {"schema": {"type": "string", "format": "binary"}}
            },
        },
    )
    @ingest_blp.arguments(OffsetSchema, location="query")
    @ingest_blp.response(200, LogStatusSchema)
    @ingest_blp.alt_response(409, description="`received`: where the master's copy ends")
    def put(self, query: dict[str, Any], remote_run_id: int, filename: str) -> Any:
        """Send a piece of a log (at most 64 MiB) starting at `offset`; once the log is whole,
        the master checks its size and SHA-256 and stores it (a mismatch: 422, send it again)."""
        request.max_content_length = CHUNK_LIMIT
        try:
            return _recording(
                remote_run_id,
                lambda: ingest.receive_chunk(
                    _instance(), remote_run_id, filename, query["offset"], request.stream
                ),
            )
        except ingest.OffsetMismatch as exc:
            return {"code": 409, "message": str(exc), "received": exc.received}, 409

    @ingest_blp.doc(security=UPLOAD_SECURITY)
    @ingest_blp.response(200, LogStatusSchema)
    def get(self, remote_run_id: int, filename: str) -> Any:
        """How much of one log the master has: send the rest from `received`."""
        run = ingest.uploaded_run(_instance(), remote_run_id)
        if run is None:
            raise NotFound.of("uploaded run", remote_run_id)
        return ingest.log_status(run, filename)


@ingest_blp.route("/portal/ingest/runs/<int:remote_run_id>/complete")
class CompletedUpload(MethodView):
    @ingest_blp.doc(security=UPLOAD_SECURITY)
    @ingest_blp.response(200, UploadStatusSchema)
    def post(self, remote_run_id: int) -> Any:
        """Acknowledge the upload: every declared log is stored (409 names the missing ones)."""
        return ingest.run_status(ingest.complete(_instance(), remote_run_id))


@blp.route("/portal/refusals")
class Refusals(MethodView):
    @blp.response(200, RefusalSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List every result the portal refused and why, newest first (officers)."""
        return review.refusals(caller())


@blp.route("/runs/<int:run_id>/review")
class RunReview(MethodView):
    @blp.arguments(ReviewSchema)
    @blp.response(200, RunSchema)
    @blp.alt_response(
        409,
        description="reinstating while another finished run of the task counts; accepting a "
        "run that is not held",
    )
    def patch(self, data: dict[str, Any], run_id: int) -> Any:
        """Set an officer's note on a run, invalidate it (`reason` required: it no longer
        counts in the ranking) or count it again, or accept a run held for review (officers;
        audited)."""
        return review.review_run(
            caller(),
            run_id,
            note=data["note"] if "note" in data else ...,
            invalidated=data.get("invalidated"),
            reason=data.get("reason"),
            accepted=data.get("accepted"),
        )
