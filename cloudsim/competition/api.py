"""Tasks, the season schedule, runs, their logs and the leaderboard."""

from __future__ import annotations

from typing import Any

from flask import current_app
from flask.views import MethodView
from marshmallow import Schema, fields, validate
from sqlalchemy.orm import selectinload

from cloudsim.api.common import Blueprint, SelectPage, caller
from cloudsim.competition import live_view, schedule, season
from cloudsim.competition import runs as run_service
from cloudsim.models import Run, RunState, UploadState
from cloudsim.web.inputs import INT64_MAX, Id, Int

blp = Blueprint("api_competition", __name__, description="Tasks, runs, logs and scores")


class TaskSchema(Schema):
    id = fields.Int(dump_only=True)
    team_id = fields.Int(dump_only=True)
    phase_id = fields.Int(
        dump_only=True,
        allow_none=True,
        metadata={"description": "the season's phase it was made from; null: scheduled by hand"},
    )
    name = fields.Str()
    world = fields.Str()
    run_config = fields.Int()
    window_start = fields.DateTime()
    window_stop = fields.DateTime()
    time_zone = fields.Str()
    timeout_s = fields.Int()
    latency_ms = fields.Int()
    uplink_bits = fields.Int()
    downlink_bits = fields.Int()
    order = fields.Int()


class TaskCreateSchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(min=1, max=120))
    world = fields.Str(required=True, validate=validate.Length(min=1, max=64))
    run_config = Int(load_default=1)
    start = fields.Str(
        required=True, metadata={"description": "Wall-clock time in time_zone, or ISO 8601"}
    )
    stop = fields.Str(required=True)
    time_zone = fields.Str(load_default="UTC", validate=validate.Length(min=1, max=64))
    timeout_s = Int(load_default=schedule.DEFAULT_TIMEOUT_S)
    latency_ms = Int(load_default=schedule.DEFAULT_LATENCY_MS)
    uplink_bits = Int(load_default=schedule.DEFAULT_UPLINK_BITS, maximum=INT64_MAX)
    downlink_bits = Int(load_default=schedule.DEFAULT_DOWNLINK_BITS, maximum=INT64_MAX)
    order = Int(load_default=0)
    team_ids = fields.List(
        Id(),
        load_default=None,
        allow_none=True,
        metadata={"description": "Teams to schedule it for; null or left out: every team"},
    )


class SeasonSchema(Schema):
    yaml = fields.Str(required=True, validate=validate.Length(min=1, max=1_000_000))


class StartSchema(Schema):
    constellation_id = Id(load_default=None, allow_none=True)


class ScoreEventSchema(Schema):
    kind = fields.Str()
    checkpoint = fields.Int(allow_none=True)
    points = fields.Int()
    sim_time = fields.Float()
    wall_time = fields.DateTime()
    description = fields.Str()


class ArtifactSchema(Schema):
    id = fields.Int()
    kind = fields.Str()
    filename = fields.Str()
    size = fields.Int()
    sha256 = fields.Str()
    created_at = fields.DateTime()


class RunUploadSchema(Schema):
    state = fields.Str(
        metadata={
            "description": "pending, uploading, uploaded or refused",
            "enum": list(UploadState),
        }
    )
    percent = fields.Int(metadata={"description": "how much of the run's logs the master has"})
    portal_run_id = fields.Int(
        allow_none=True, metadata={"description": "the run's id on the master (its portal)"}
    )
    error = fields.Str(
        allow_none=True,
        metadata={"description": "refused: why; pending or uploading: the last failure"},
    )
    next_attempt_at = fields.DateTime(
        allow_none=True,
        metadata={"description": "pending or uploading: when it is sent (again); else null"},
    )


class UploadField(fields.Nested):
    """A run's upload to the master's portal, as a team instance sees it (null: none)."""

    def _serialize(self, nested_obj: Any, attr: Any, obj: Any, **kwargs: Any) -> Any:  # type: ignore[override]  # Nested renames Field's value
        run, value = obj, nested_obj
        if value is None:
            ended = run.state in (RunState.FINISHED, RunState.ERROR)
            if not (ended and run.task.master_key):
                return None  # a master's run, an instance's own task's, a live one
            # the master's task's ended run: the next upload beat gives it its outbox row
            status = {"state": UploadState.PENDING, "percent": 0}
        else:
            waiting = value.state in (UploadState.PENDING, UploadState.UPLOADING)
            status = {
                "state": value.state,
                "percent": value.percent,
                "portal_run_id": value.master_run_id,
                "error": value.error,
                "next_attempt_at": value.next_attempt_at if waiting else None,
            }
        return super()._serialize(
            dict.fromkeys(("portal_run_id", "error", "next_attempt_at")) | status, attr, obj
        )


class RunSchema(Schema):
    id = fields.Int()
    task_id = fields.Int()
    team_id = fields.Int()
    constellation_id = fields.Int(allow_none=True)
    state = fields.Str(
        metadata={"description": "starting, running, stopping, finished, error, needs_review"}
    )
    stop_reason = fields.Str(allow_none=True)
    end_reason = fields.Str(allow_none=True)
    error = fields.Str(allow_none=True)
    error_code = fields.Str(
        allow_none=True, metadata={"description": "a stable code of docs/error-codes.md"}
    )
    score = fields.Int()
    falls = fields.Int()
    sim_seconds = fields.Float()
    uplink_bits_used = fields.Int()
    downlink_bits_used = fields.Int()
    uplink_spent_at = fields.DateTime(
        allow_none=True,
        metadata={"description": "When the uplink cap was spent (dropped since); null if not"},
    )
    downlink_spent_at = fields.DateTime(
        allow_none=True,
        metadata={"description": "When the downlink cap was spent; null if not"},
    )
    started_at = fields.DateTime()
    running_at = fields.DateTime(allow_none=True)
    finished_at = fields.DateTime(allow_none=True)
    instance_id = fields.Int(
        allow_none=True, metadata={"description": "the team instance it was uploaded from"}
    )
    remote_run_id = fields.Int(allow_none=True, metadata={"description": "its id there"})
    officer_note = fields.Str(allow_none=True)
    invalidated_at = fields.DateTime(
        allow_none=True, metadata={"description": "set: an officer invalidated it, not ranked"}
    )
    invalid_reason = fields.Str(allow_none=True)
    verification = fields.Str(
        allow_none=True,
        metadata={
            "description": "what re-simulating the run from its logs found: verifying, verified, "
            "held (for review; not ranked), accepted (by an officer); null: not verified yet"
        },
    )
    verification_reason = fields.Str(
        allow_none=True, metadata={"description": "why the run is held"}
    )
    verified_at = fields.DateTime(allow_none=True)
    upload = UploadField(
        RunUploadSchema,
        allow_none=True,
        metadata={
            "description": "on a team instance: the run's upload to the master's portal; null "
            "for a run that is not uploaded (a master's own, a live one, an instance's own task's)"
        },
    )


class RunDetailSchema(RunSchema):
    score_events = fields.List(fields.Nested(ScoreEventSchema))
    artifacts = fields.List(fields.Nested(ArtifactSchema))


class LiveEventSchema(Schema):
    kind = fields.Str(metadata={"description": "checkpoint, fall or run_end"})
    sim_time = fields.Float()
    wall_time = fields.Str(metadata={"description": "ISO 8601, UTC"})
    checkpoint = fields.Int(allow_none=True)
    points = fields.Int()
    description = fields.Str()


class FlagSchema(Schema):
    code = fields.Str(metadata={"description": "a code of docs/error-codes.md"})
    cause = fields.Str()
    remedy = fields.Str()
    figures = fields.Str(required=False)


def _directions(description: str) -> fields.Dict:
    return fields.Dict(
        keys=fields.Str(), values=fields.Raw(allow_none=True), metadata={"description": description}
    )


class RunLiveSchema(Schema):
    id = fields.Int()
    state = fields.Str()
    since = fields.Str(allow_none=True, metadata={"description": "when it entered its state"})
    live = fields.Bool(
        metadata={"description": "true: the figures are the live reader's, at most a few s old"}
    )
    score = fields.Int()
    falls = fields.Int()
    sim_seconds = fields.Float(metadata={"description": "simulated time, live from the simulator"})
    timeout_s = fields.Int()
    rtf = fields.Float(allow_none=True, metadata={"description": "real-time factor, last second"})
    end_reason = fields.Str(allow_none=True)
    error = fields.Str(allow_none=True)
    error_code = fields.Str(allow_none=True, metadata={"description": "docs/error-codes.md"})
    bits_used = _directions("payload bits used, uplink and downlink")
    caps = _directions("the task's caps in bits, uplink and downlink")
    bits_left = _directions("bits left under each cap")
    spent_since = _directions("when each cap was spent (ISO 8601), null while it lasts")
    caps_spent = fields.Str()
    events = fields.List(fields.Nested(LiveEventSchema))
    heard = _directions(
        "when CloudSim last heard from each machine of the run (sim, router, field computers)"
    )
    flags = fields.List(
        fields.Nested(FlagSchema), metadata={"description": "what is wrong now (running runs)"}
    )


class StandingSchema(Schema):
    rank = fields.Int()
    team_id = fields.Int()
    team = fields.Str()
    runs = fields.Int()
    checkpoints = fields.Int()
    uplink_share_left = fields.Float()
    seconds_left = fields.Float()
    invalidated = fields.Int(
        metadata={"description": "the team's finished runs an officer invalidated: not ranked"}
    )
    unverified = fields.Int(
        metadata={
            "description": "of the team's ranked runs, those not verified by replay yet "
            "(CLOUDSIM_RANK_UNVERIFIED)"
        }
    )
    held = fields.Int(
        metadata={"description": "the team's finished runs held for review: not ranked"}
    )


@blp.route("/tasks")
class Tasks(MethodView):
    @blp.response(200, TaskSchema(many=True))
    @blp.paginate(SelectPage, page_size=100, max_page_size=1000)
    def get(self) -> Any:
        """List tasks (a team user: their team's whose window has opened)."""
        return schedule.visible_tasks(caller())

    @blp.arguments(TaskCreateSchema)
    @blp.response(201, TaskSchema(many=True))
    def post(self, data: dict[str, Any]) -> Any:
        """Schedule a task for some teams or every team (officers); one task per team."""
        spec = schedule.TaskSpec(
            name=data["name"],
            world=data["world"],
            run_config=data["run_config"],
            window_start=schedule.to_utc(data["start"], data["time_zone"]),
            window_stop=schedule.to_utc(data["stop"], data["time_zone"]),
            timeout_s=data["timeout_s"],
            latency_ms=data["latency_ms"],
            uplink_bits=data["uplink_bits"],
            downlink_bits=data["downlink_bits"],
            order=data["order"],
            time_zone=data["time_zone"],
        )
        return schedule.schedule(caller(), spec, data["team_ids"])


@blp.route("/tasks/open")
class OpenTasks(MethodView):
    @blp.response(200, TaskSchema(many=True))
    def get(self) -> Any:
        """List the tasks whose window is open now (a team user: their team's)."""
        return schedule.open_tasks(caller())


@blp.route("/tasks/<int:task_id>")
class TaskById(MethodView):
    @blp.response(200, TaskSchema)
    def get(self, task_id: int) -> Any:
        """Return a task."""
        return schedule.get_task(caller(), task_id)

    @blp.response(204)
    def delete(self, task_id: int) -> None:
        """Delete a task nobody has run (officers)."""
        schedule.delete_task(caller(), task_id)


@blp.route("/tasks/<int:task_id>/runs")
class StartRun(MethodView):
    @blp.arguments(StartSchema)
    @blp.response(202, RunSchema)
    def post(self, data: dict[str, Any], task_id: int) -> Any:
        """Start a run of an open task on the team's ready constellation; follow its state."""
        return run_service.start_run(caller(), task_id, data["constellation_id"])


@blp.route("/schedule")
class Season(MethodView):
    @blp.response(200, SeasonSchema)
    def get(self) -> Any:
        """Export the season's schedule as YAML (officers)."""
        return {"yaml": season.export_season(caller())}

    @blp.arguments(SeasonSchema)
    @blp.response(201, TaskSchema(many=True))
    def post(self, data: dict[str, Any]) -> Any:
        """Import a season's schedule from YAML (officers); tasks already there are kept."""
        return season.import_season(caller(), data["yaml"])


@blp.route("/runs")
class Runs(MethodView):
    @blp.response(200, RunSchema(many=True))
    @blp.paginate(SelectPage, page_size=50, max_page_size=500)
    def get(self) -> Any:
        """List runs (a team user: their team's)."""
        return run_service.visible_runs(caller()).options(selectinload(Run.upload))


@blp.route("/runs/<int:run_id>")
class RunById(MethodView):
    @blp.response(200, RunDetailSchema)
    def get(self, run_id: int) -> Any:
        """Return a run with its score events and logs."""
        return run_service.get_run(caller(), run_id)


@blp.route("/runs/<int:run_id>/live")
class RunLive(MethodView):
    @blp.response(200, RunLiveSchema)
    def get(self, run_id: int) -> Any:
        """Get a run's figures now: live (refreshed each second) while it runs, else final."""
        run = run_service.get_run(caller(), run_id)
        return live_view.live_status(current_app.config["CLOUDSIM"], run)


@blp.route("/runs/<int:run_id>/stop")
class StopRun(MethodView):
    @blp.response(202, RunSchema)
    def post(self, run_id: int) -> Any:
        """Stop a live run (its team, or officers)."""
        return run_service.stop_run(caller(), run_id)


@blp.route("/runs/<int:run_id>/logs/<int:artifact_id>")
class RunLog(MethodView):
    @blp.response(200, content_type="application/octet-stream")
    def get(self, run_id: int, artifact_id: int) -> Any:
        """Download one of the run's logs (streamed; the X-Checksum-SHA256 header to verify)."""
        return run_service.log_download(caller(), run_id, artifact_id)


@blp.route("/leaderboard")
class Leaderboard(MethodView):
    @blp.response(200, StandingSchema(many=True))
    def get(self) -> Any:
        """Return the ranking (what team users see is the leaderboard setting)."""
        return run_service.leaderboard(caller())
