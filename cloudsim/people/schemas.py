"""Request and response schemas of the people API: teams and users."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.models import Role
from cloudsim.web.inputs import Id


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
    team_id = Id(allow_none=True, load_default=None)
    active = fields.Bool(dump_only=True)
    created_at = fields.DateTime(dump_only=True)
    last_login_at = fields.DateTime(dump_only=True, allow_none=True)


class UserCreateSchema(UserSchema):
    password = fields.Str(load_only=True, load_default=None, validate=validate.Length(max=256))


class UserCreatedSchema(UserSchema):
    generated_password = fields.Str(
        allow_none=True, metadata={"description": "Set when CloudSim chose the password"}
    )


class UserUpdateSchema(Schema):
    name = fields.Str(validate=validate.Length(max=120))
    role = fields.Str(validate=validate.OneOf([r.value for r in Role]))
    team_id = Id(allow_none=True)
    active = fields.Bool()
    password = fields.Str(load_only=True, validate=validate.Length(max=256))
