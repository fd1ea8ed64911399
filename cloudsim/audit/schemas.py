"""Request and response schemas of the audit API."""

from __future__ import annotations

from marshmallow import Schema, fields, validate


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
