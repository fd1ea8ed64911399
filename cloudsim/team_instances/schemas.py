"""Request and response schemas of the team instances API (master side and instance side)."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.jobs.schemas import JobSchema
from cloudsim.web.inputs import Id, When


class HealthSchema(Schema):
    version = fields.Str()
    database = fields.Bool()
    queue = fields.Bool()
    worker = fields.Bool()
    worker_seen_seconds_ago = fields.Float(allow_none=True)


class SyncResultSchema(Schema):
    changed = fields.List(fields.Str(), metadata={"description": "what this sync changed"})
    reported = fields.List(
        fields.Str(), metadata={"description": "what it found and left for people to decide"}
    )
    drift = fields.List(
        fields.Str(),
        metadata={
            "description": "the changes that put back what was changed on the instance by hand"
        },
    )


class TeamInstanceSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    team_id = fields.Int(allow_none=True)
    constellation_id = fields.Int()
    state = fields.Str(
        metadata={"description": "deploying, ready, unreachable, error or terminated"}
    )
    url = fields.Str(allow_none=True, metadata={"description": "HTTPS only"})
    cert_fingerprint = fields.Str(
        allow_none=True, metadata={"description": "SHA-256 of the pinned certificate"}
    )
    version = fields.Str(allow_none=True)
    health = fields.Nested(HealthSchema)
    error = fields.Str(allow_none=True)
    checked_at = fields.DateTime(allow_none=True)
    heard_at = fields.DateTime(
        allow_none=True,
        metadata={"description": "when it last answered the master (a health check or a sync)"},
    )
    last_sync_at = fields.DateTime(allow_none=True)
    sync_error = fields.Str(allow_none=True)
    sync_report = fields.Nested(
        SyncResultSchema,
        metadata={
            "description": "what the last sync changed, which of it was drift put back, and "
            "what it reported; every drift is also in the audit log (team_instance.drift)"
        },
    )
    launch = fields.Dict(
        allow_none=True,
        metadata={
            "description": "the constellation launched through it, as last polled: kind, "
            "provider, state, stage, progress, error, constellation_id and job_id (the "
            "instance's), seen_at, poll_error"
        },
    )
    created_at = fields.DateTime()


class TeamInstanceStatusSchema(TeamInstanceSchema):
    job_kind = fields.Str(
        allow_none=True,
        metadata={"description": "its latest job (its own: sync, launch; its constellation's)"},
    )
    job_state = fields.Str(allow_none=True)
    step = fields.Str(allow_none=True, metadata={"description": "the latest job's current step"})
    step_since = fields.Str(
        allow_none=True, metadata={"description": "when it entered that step (ISO 8601)"}
    )


class DeploySchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(min=1, max=21))
    provider = fields.Str(load_default="local", validate=validate.Length(min=1, max=32))
    team_id = Id(allow_none=True, load_default=None)
    count = fields.Int(
        load_default=1,
        validate=validate.Range(min=1, max=50),
        metadata={"description": "more than 1: spares NAME-1..NAME-N, assigned later"},
    )


class DeployedSchema(Schema):
    instance = fields.Nested(TeamInstanceSchema)
    job = fields.Nested(JobSchema)


class AssignSchema(Schema):
    team_id = Id(required=True)


class DesiredKeySchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(max=80))
    public_key = fields.Str(required=True, validate=validate.Length(min=1, max=16000))


class DesiredUserSchema(Schema):
    email = fields.Email(required=True, validate=validate.Length(max=254))
    name = fields.Str(required=True, validate=validate.Length(max=120))
    role = fields.Str(required=True, validate=validate.OneOf(["user", "officer"]))
    active = fields.Bool(required=True)
    password_hash = fields.Str(
        required=True,
        validate=[validate.Length(max=255), validate.Regexp(r"\$argon2id\$")],
        metadata={"description": "the master's Argon2id hash: the same password logs in"},
    )
    ssh_keys = fields.List(
        fields.Nested(DesiredKeySchema), required=True, validate=validate.Length(max=20)
    )


class DesiredTaskSchema(Schema):
    key = fields.Str(
        required=True,
        validate=validate.Length(min=1, max=32),
        metadata={"description": "the master's name for the task (m<id>)"},
    )
    name = fields.Str(required=True, validate=validate.Length(min=1, max=120))
    world = fields.Str(required=True, validate=validate.Length(min=1, max=64))
    run_config = fields.Int(required=True, validate=validate.Range(min=1, max=100))
    window_start = When(required=True)
    window_stop = When(required=True)
    time_zone = fields.Str(required=True, validate=validate.Length(min=1, max=64))
    timeout_s = fields.Int(required=True, validate=validate.Range(min=1, max=86_400))
    latency_ms = fields.Int(required=True, validate=validate.Range(min=0, max=10_000))
    uplink_bits = fields.Int(required=True, validate=validate.Range(min=0, max=2**62))
    downlink_bits = fields.Int(required=True, validate=validate.Range(min=0, max=2**62))
    order = fields.Int(required=True, validate=validate.Range(min=-10_000, max=10_000))


class DesiredWorldSchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(min=1, max=64))
    version = fields.Int(required=True, validate=validate.Range(min=1, max=2**31 - 1))
    digest = fields.Str(
        required=True,
        validate=validate.Regexp(r"^[0-9a-f]{64}$"),
        metadata={"description": "SHA-256 of the document's canonical JSON"},
    )
    document = fields.Dict(
        required=True, metadata={"description": "the world document (drcsim's format)"}
    )


class DesiredPortalSchema(Schema):
    url = fields.Str(
        required=True,
        validate=[validate.Length(max=255), validate.Regexp(r"^https://[^/\s]+:[0-9]+/$")],
        metadata={"description": "the master's portal: https://HOST:PORT/"},
    )
    ca_cert = fields.Str(required=True, validate=validate.Length(min=1, max=20_000))
    fingerprint = fields.Str(
        required=True,
        validate=validate.Regexp(r"^[0-9a-f]{64}$"),
        metadata={"description": "SHA-256 of the portal's certificate: pinned"},
    )
    token = fields.Str(
        required=True,
        validate=[validate.Length(max=200), validate.Regexp(r"^cspu_")],
        metadata={"description": "the instance's upload token (kept encrypted)"},
    )


class DesiredStateSchema(Schema):
    team = fields.Str(
        allow_none=True,
        load_default=None,
        validate=validate.Length(min=1, max=80),
        metadata={"description": "the instance's team (none: a spare)"},
    )
    portal = fields.Nested(
        DesiredPortalSchema,
        allow_none=True,
        load_default=None,
        metadata={"description": "how to upload finished runs to the master (none: do not)"},
    )
    users = fields.List(
        fields.Nested(DesiredUserSchema), required=True, validate=validate.Length(max=10_000)
    )
    tasks = fields.List(
        fields.Nested(DesiredTaskSchema), required=True, validate=validate.Length(max=10_000)
    )
    worlds = fields.List(
        fields.Nested(DesiredWorldSchema),
        load_default=None,
        validate=validate.Length(max=100),
        metadata={"description": "every world definition (absent: the worlds are left alone)"},
    )


class InstanceProviderSchema(Schema):
    provider = fields.Str(required=True, validate=validate.Length(min=1, max=32))
    settings = fields.Dict(
        required=True,
        metadata={"description": 'e.g. servers: {"inventory": [...]}; kept encrypted'},
    )


class LaunchThroughSchema(Schema):
    kind = fields.Str(load_default="vrc", validate=validate.Length(min=1, max=32))
    provider = fields.Str(load_default="servers", validate=validate.Length(min=1, max=32))
    instance_ids = fields.List(
        Id(),
        load_default=None,
        validate=validate.Length(min=1, max=100),
        metadata={"description": "which instances; none: every team's"},
    )


class OutcomeSchema(Schema):
    instance_id = fields.Int()
    instance = fields.Str()
    team = fields.Str(allow_none=True)
    state = fields.Str(metadata={"description": "ready, launching or failed"})
    why = fields.Str(allow_none=True)
    job_id = fields.Str(allow_none=True, metadata={"description": "the master's launch job"})
