"""Request and response schemas of the API (they also make its OpenAPI description)."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.models import JobState, Role


class TeamSchema(Schema):
    id = fields.Int(dump_only=True)
    name = fields.Str(required=True, validate=validate.Length(min=1, max=80))
    created_at = fields.DateTime(dump_only=True)


class UserSchema(Schema):
    id = fields.Int(dump_only=True)
    email = fields.Str(required=True, validate=validate.Length(min=3, max=254))
    name = fields.Str(load_default="", validate=validate.Length(max=120))
    role = fields.Str(
        load_default=Role.USER.value, validate=validate.OneOf([r.value for r in Role])
    )
    team_id = fields.Int(allow_none=True, load_default=None)
    active = fields.Bool(dump_only=True)
    created_at = fields.DateTime(dump_only=True)
    last_login_at = fields.DateTime(dump_only=True)


class UserCreateSchema(UserSchema):
    password = fields.Str(load_only=True, load_default=None, validate=validate.Length(max=256))


class UserCreatedSchema(UserSchema):
    generated_password = fields.Str(
        allow_none=True, metadata={"description": "Set when CloudSim chose the password"}
    )


class UserUpdateSchema(Schema):
    name = fields.Str(validate=validate.Length(max=120))
    role = fields.Str(validate=validate.OneOf([r.value for r in Role]))
    team_id = fields.Int(allow_none=True)
    active = fields.Bool()
    password = fields.Str(load_only=True, validate=validate.Length(max=256))


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


class AuditEventSchema(Schema):
    id = fields.Int()
    at = fields.DateTime()
    actor = fields.Str()
    action = fields.Str()
    target_type = fields.Str(allow_none=True)
    target_id = fields.Str(allow_none=True)
    team_id = fields.Int(allow_none=True)
    details = fields.Dict()
    address = fields.Str(allow_none=True)


class AuditQuerySchema(Schema):
    action = fields.Str(validate=validate.Length(max=64))


class TokenSchema(Schema):
    id = fields.Int(dump_only=True)
    name = fields.Str(required=True, validate=validate.Length(min=1, max=80))
    prefix = fields.Str(dump_only=True)
    created_at = fields.DateTime(dump_only=True)
    last_used_at = fields.DateTime(dump_only=True, allow_none=True)
    revoked_at = fields.DateTime(dump_only=True, allow_none=True)


class IssuedTokenSchema(TokenSchema):
    token = fields.Str(dump_only=True, metadata={"description": "Shown this once only"})


class MachineSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    role = fields.Str()
    state = fields.Str()
    private_ip = fields.Str(allow_none=True)
    public_ip = fields.Str(allow_none=True)
    verification = fields.Dict()


class ConstellationSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    kind = fields.Str()
    provider = fields.Str()
    team_id = fields.Int(allow_none=True)
    state = fields.Str()
    error = fields.Str(allow_none=True)
    created_at = fields.DateTime()
    machines = fields.List(fields.Nested(MachineSchema))


class LaunchSchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(min=1, max=24))
    kind = fields.Str(required=True, validate=validate.Length(min=1, max=32))
    provider = fields.Str(load_default="local", validate=validate.Length(min=1, max=32))
    team_id = fields.Int(allow_none=True, load_default=None)


class LaunchedSchema(Schema):
    constellation = fields.Nested(ConstellationSchema)
    job = fields.Nested(JobSchema)


class VpnBundleQuerySchema(Schema):
    user_id = fields.Int(metadata={"description": "Officers: whose bundle (default: yours)"})
