"""The viewer's query strings, checked alike for its pages' JSON and for the API."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.viewer.service import MAX_CHUNK_SECONDS


class FramesQuery(Schema):
    start = fields.Float(load_default=0.0, validate=validate.Range(min=0), allow_nan=False)
    seconds = fields.Float(
        load_default=5.0,
        validate=validate.Range(min=0, max=MAX_CHUNK_SECONDS, min_inclusive=False),
        allow_nan=False,
    )


class LiveQuery(Schema):
    after = fields.Float(load_default=-1.0, allow_nan=False)
    viewer = fields.Str(load_default="", validate=validate.Length(max=64))
