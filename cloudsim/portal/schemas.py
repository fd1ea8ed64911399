"""Request and response schemas of the portal's ingest API (instances) and review API (officers)."""

from __future__ import annotations

from drcsim.rundir import SCORE_EVENTS
from marshmallow import Schema, fields, validate

from cloudsim.web.inputs import INT64_MAX, Int, When

LOG_NAME = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,200}$"
BITS = validate.Range(min=0, max=INT64_MAX)
WHEN = {"format": "ISO 8601 with a zone"}


class UploadedScoreEventSchema(Schema):
    kind = fields.Str(required=True, validate=validate.OneOf(SCORE_EVENTS))
    checkpoint = Int(minimum=0, allow_none=True, load_default=None)
    points = Int(minimum=0, maximum=1000, load_default=0)
    sim_time = fields.Float(required=True, validate=validate.Range(min=0, max=1e7))
    wall_time = When(required=True, metadata=WHEN)
    description = fields.Str(load_default="", validate=validate.Length(max=255))


class DeclaredLogSchema(Schema):
    filename = fields.Str(required=True, validate=validate.Regexp(LOG_NAME))
    kind = fields.Str(required=True, validate=validate.Length(min=1, max=32))
    size = fields.Int(required=True, validate=BITS, metadata={"description": "bytes"})
    sha256 = fields.Str(required=True, validate=validate.Regexp(r"^[0-9a-f]{64}$"))


class RunRecordSchema(Schema):
    """A finished run as a team instance sends it (its logs follow, piece by piece)."""

    team = fields.Str(
        required=True,
        validate=validate.Length(min=1, max=80),
        metadata={"description": "the instance's team: the only one it may send results for"},
    )
    task_key = fields.Str(
        required=True,
        validate=validate.Length(min=1, max=32),
        metadata={"description": "the master's task (m<id>), as the desired state named it"},
    )
    task_name = fields.Str(required=True, validate=validate.Length(max=120))
    world = fields.Str(required=True, validate=validate.Length(min=1, max=64))
    run_config = Int(required=True, minimum=1, maximum=100)
    state = fields.Str(required=True, validate=validate.OneOf(["finished", "error"]))
    stop_reason = fields.Str(allow_none=True, load_default=None, validate=validate.Length(max=32))
    end_reason = fields.Str(allow_none=True, load_default=None, validate=validate.Length(max=32))
    error = fields.Str(allow_none=True, load_default=None, validate=validate.Length(max=10_000))
    score = Int(required=True, minimum=0, maximum=1000)
    falls = Int(required=True, minimum=0, maximum=1000)
    sim_seconds = fields.Float(required=True, validate=validate.Range(min=0, max=1e7))
    uplink_bits_used = fields.Int(required=True, validate=BITS)
    downlink_bits_used = fields.Int(required=True, validate=BITS)
    uplink_bits = fields.Int(required=True, validate=BITS, metadata={"description": "the cap"})
    downlink_bits = fields.Int(required=True, validate=BITS, metadata={"description": "the cap"})
    timeout_s = Int(required=True, minimum=1, maximum=86_400)
    seconds_left = fields.Float(required=True, validate=validate.Range(min=0, max=1e7))
    uplink_spent_at = When(allow_none=True, load_default=None, metadata=WHEN)
    downlink_spent_at = When(allow_none=True, load_default=None, metadata=WHEN)
    started_at = When(required=True, metadata=WHEN)
    running_at = When(allow_none=True, load_default=None, metadata=WHEN)
    finished_at = When(required=True, allow_none=True, metadata=WHEN)
    score_events = fields.List(
        fields.Nested(UploadedScoreEventSchema),
        required=True,
        validate=validate.Length(max=10_000),
    )
    logs = fields.List(
        fields.Nested(DeclaredLogSchema), required=True, validate=validate.Length(max=50)
    )


class LogStatusSchema(Schema):
    filename = fields.Str()
    size = fields.Int()
    sha256 = fields.Str()
    received = fields.Int(metadata={"description": "bytes the master has: send from here"})
    complete = fields.Bool(metadata={"description": "stored, its checksum verified"})


class UploadStatusSchema(Schema):
    run_id = fields.Int(metadata={"description": "the run's id on the master"})
    logs = fields.List(fields.Nested(LogStatusSchema))
    complete = fields.Bool(metadata={"description": "every declared log is stored"})


class OffsetSchema(Schema):
    offset = fields.Int(
        required=True,
        validate=BITS,
        metadata={"description": "where this piece starts: the master's `received`"},
    )


class RefusalSchema(Schema):
    id = fields.Int()
    instance_id = fields.Int(allow_none=True)
    instance = fields.Str(attribute="instance.name", allow_none=True)
    team_id = fields.Int(allow_none=True)
    remote_run_id = fields.Int(allow_none=True, metadata={"description": "the instance's run id"})
    run_id = fields.Int(allow_none=True, metadata={"description": "the master's run, if any"})
    reason = fields.Str()
    detail = fields.Dict()
    created_at = fields.DateTime()


class ReviewSchema(Schema):
    note = fields.Str(
        allow_none=True,
        validate=validate.Length(max=2000),
        metadata={"description": "an officer's note on the run; empty or null removes it"},
    )
    invalidated = fields.Bool(
        metadata={"description": "true: the run no longer counts (give a reason); false: again"}
    )
    accepted = fields.Bool(
        metadata={
            "description": "true: accept a run its verification held for review (it is ranked "
            "again; `reason` is recorded in the audit log)"
        }
    )
    reason = fields.Str(validate=validate.Length(max=2000))
