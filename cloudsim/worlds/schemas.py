"""Request and response schemas of the worlds API."""

from __future__ import annotations

from marshmallow import Schema, fields


class WorldSchema(Schema):
    name = fields.Str()
    title = fields.Method("_title")
    version = fields.Int(metadata={"description": "bumped by every change of the document"})
    digest = fields.Str(metadata={"description": "SHA-256 of the document's canonical JSON"})
    configs = fields.Method("_configs", metadata={"description": "run configuration numbers"})
    updated_at = fields.DateTime()

    def _title(self, world: object) -> str:
        return str(getattr(world, "document", {}).get("title", ""))

    def _configs(self, world: object) -> list[int]:
        return sorted(int(key) for key in getattr(world, "document", {}).get("configs", {}))


class WorldDocumentSchema(WorldSchema):
    document = fields.Dict(metadata={"description": "the world document (drcsim's format)"})


class WorldUploadSchema(Schema):
    document = fields.Dict(
        required=True,
        metadata={"description": "the whole world document, checked by drcsim's schema"},
    )


class WorldUpdatedSchema(Schema):
    world = fields.Nested(WorldDocumentSchema)
    changed = fields.Bool(metadata={"description": "false: the same document was stored"})
