"""Request and response schemas of the caller's API tokens and SSH keys."""

from __future__ import annotations

from marshmallow import Schema, fields, validate


class TokenSchema(Schema):
    id = fields.Int(dump_only=True)
    name = fields.Str(required=True, validate=validate.Length(min=1, max=80))
    prefix = fields.Str(dump_only=True)
    created_at = fields.DateTime(dump_only=True)
    last_used_at = fields.DateTime(dump_only=True, allow_none=True)
    revoked_at = fields.DateTime(dump_only=True, allow_none=True)


class IssuedTokenSchema(TokenSchema):
    token = fields.Str(dump_only=True, metadata={"description": "Shown this once only"})


class SshKeySchema(Schema):
    id = fields.Int(dump_only=True)
    name = fields.Str(load_default="", validate=validate.Length(max=80))
    public_key = fields.Str(
        load_default=None,
        validate=validate.Length(max=16384),
        metadata={"description": "One OpenSSH public key line: ed25519, ecdsa or rsa >= 3072"},
    )
    generate = fields.Bool(
        load_only=True,
        load_default=False,
        metadata={"description": "Make an ed25519 key instead; its private key is answered once"},
    )
    key_type = fields.Str(dump_only=True)
    bits = fields.Int(dump_only=True)
    fingerprint = fields.Str(dump_only=True)
    created_at = fields.DateTime(dump_only=True)


class GeneratedSshKeySchema(SshKeySchema):
    private_key = fields.Str(
        dump_only=True, metadata={"description": "Shown this once only; never stored"}
    )
