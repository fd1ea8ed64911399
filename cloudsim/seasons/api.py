"""The season's phases: read their rules, schedule a phase's tasks, reveal hidden scores."""

from __future__ import annotations

from typing import Any

from flask.views import MethodView
from marshmallow import Schema, fields

from cloudsim.api.common import Blueprint, caller
from cloudsim.competition.api import TaskSchema
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.models import Phase
from cloudsim.seasons import service

blp = Blueprint(
    "api_seasons",
    __name__,
    description="The season's phases and their rules (written through the season YAML, "
    "POST /api/v1/schedule)",
)


class LimitsSchema(Schema):
    per_task = fields.Int(
        attribute="max_runs_per_task",
        allow_none=True,
        metadata={"description": "runs of each VRC task (world) per team; null: no limit"},
    )
    per_day = fields.Int(
        attribute="max_runs_per_day",
        allow_none=True,
        metadata={"description": "runs a day per team (days in the phase's time zone)"},
    )
    total = fields.Int(attribute="max_runs_total", allow_none=True)
    at_once = fields.Int(attribute="max_runs_at_once", allow_none=True)


class PhaseSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    position = fields.Int()
    window_start = fields.DateTime()
    window_stop = fields.DateTime()
    time_zone = fields.Str()
    worlds = fields.Method(
        "_worlds", metadata={"description": "[{world, config}]: one task of each per team"}
    )
    timeout_s = fields.Int()
    latency_ms = fields.Int()
    uplink_bits = fields.Int()
    downlink_bits = fields.Int()
    entry_after = fields.Str(
        attribute="entry_phase.name",
        allow_none=True,
        metadata={"description": "the earlier phase that qualifies teams; null: every team"},
    )
    entry_min_score = fields.Int(allow_none=True)
    limits = fields.Function(lambda phase: LimitsSchema().dump(phase))
    scores = fields.Function(lambda phase: "hidden" if phase.scores_hidden else "live")
    revealed_at = fields.DateTime(allow_none=True)
    counts_in_ranking = fields.Bool()

    def _worlds(self, phase: Phase) -> list[dict[str, Any]]:
        return [{"world": world, "config": config} for world, config in phase.worlds]


def _phase(phase_id: int) -> Phase:
    phase = db.session.get(Phase, phase_id)
    if phase is None:
        raise NotFound.of("phase", phase_id)
    return phase


@blp.route("/phases")
class Phases(MethodView):
    @blp.response(200, PhaseSchema(many=True))
    def get(self) -> Any:
        """List the season's phases and their rules (every signed-in person)."""
        caller()
        return service.list_phases()


@blp.route("/phases/<int:phase_id>")
class PhaseById(MethodView):
    @blp.response(200, PhaseSchema)
    def get(self, phase_id: int) -> Any:
        """Return a phase and its rules."""
        caller()
        return _phase(phase_id)


@blp.route("/phases/<int:phase_id>/schedule")
class SchedulePhase(MethodView):
    @blp.response(201, TaskSchema(many=True))
    def post(self, phase_id: int) -> Any:
        """Make the phase's tasks for every team that may enter it now (officers)."""
        return service.schedule_phase(caller(), _phase(phase_id))


@blp.route("/phases/<int:phase_id>/reveal")
class RevealPhase(MethodView):
    @blp.response(200, PhaseSchema)
    def post(self, phase_id: int) -> Any:
        """Show the phase's hidden scores to the teams from now on (officers; audited)."""
        return service.reveal(caller(), _phase(phase_id))
