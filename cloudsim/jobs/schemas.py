"""Request and response schemas of the jobs API."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.models import JobState


class JobSchema(Schema):
    id = fields.Str(dump_only=True)
    kind = fields.Str(required=True, validate=validate.Length(min=1, max=48))
    state = fields.Str(dump_only=True)
    stage = fields.Str(dump_only=True)
    progress = fields.Int(dump_only=True)
    error = fields.Str(dump_only=True, allow_none=True)
    target_type = fields.Str(dump_only=True, allow_none=True)
    target_id = fields.Int(dump_only=True, allow_none=True)
    team_id = fields.Int(dump_only=True, allow_none=True)
    attempts = fields.Int(dump_only=True)
    created_at = fields.DateTime(dump_only=True)
    started_at = fields.DateTime(dump_only=True, allow_none=True)
    finished_at = fields.DateTime(dump_only=True, allow_none=True)


class JobDetailSchema(JobSchema):
    log = fields.Str(dump_only=True)


class JobQuerySchema(Schema):
    state = fields.Str(validate=validate.OneOf([s.value for s in JobState]))
