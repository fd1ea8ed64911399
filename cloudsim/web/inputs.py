"""Where every request's input is parsed and bounded, before any route sees it.

Routes never meet an integer the database cannot store, a JSON document nested deeper than
any real one, a number with thousands of digits or a string that is not Unicode: the URL
converter, the JSON loader, the one integer field of the API's schemas and of the forms, and
`query_int` refuse them here with a 400/404, so no route has to.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from typing import Any

from flask import Flask, request
from flask.json.provider import DefaultJSONProvider
from flask.wrappers import Request
from marshmallow import ValidationError, fields, validate
from werkzeug.datastructures import FileStorage
from werkzeug.exceptions import BadRequest
from werkzeug.routing import IntegerConverter, Map
from wtforms import IntegerField
from wtforms.validators import NumberRange

from cloudsim.errors import InvalidInput
from cloudsim.limits import INT32_MAX, INT64_MAX

MAX_BODY_BYTES = 2 * 1024 * 1024
MAX_JSON_DEPTH = 32
MAX_FORM_PARTS = 200


class InvalidBody(ValueError):
    """A request body CloudSim refuses to read; its message is safe to show."""


class IdConverter(IntegerConverter):
    """`<int:...>` in every route: a non-negative id the database can hold, or no match (404)."""

    def __init__(self, map: Map, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("max", INT32_MAX)
        super().__init__(map, *args, **kwargs)


def id_param_schema(converter: IdConverter) -> dict[str, Any]:
    """Describe an id path parameter in the OpenAPI document."""
    return {"type": "integer", "minimum": 0, "maximum": converter.max}


def _bounded_int(text: str) -> int:
    # Twenty characters hold any 64-bit integer with its sign; longer is refused before int()
    # spends time on it (and before Python's own 4,300-digit limit raises something else).
    if len(text) > 20 or abs(value := int(text)) > INT64_MAX:
        raise InvalidBody("integers in JSON must fit in 64 bits")
    return value


def _check_tree(value: Any) -> None:
    """Refuse documents nested deeper than MAX_JSON_DEPTH and strings that are not Unicode."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > MAX_JSON_DEPTH:
            raise InvalidBody(f"JSON nested deeper than {MAX_JSON_DEPTH} levels")
        if isinstance(item, str):
            _check_text(item)
        elif isinstance(item, dict):
            for key, child in item.items():
                _check_text(key)
                stack.append((child, depth + 1))
        elif isinstance(item, list):
            stack.extend((child, depth + 1) for child in item)


def _check_text(text: str) -> None:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise InvalidBody("JSON strings must be valid Unicode (no lone surrogates)") from None


def parse_json(data: str | bytes) -> Any:
    """Parse a JSON request body within CloudSim's limits, or raise InvalidBody."""
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError:
            raise InvalidBody("the body is not UTF-8") from None
    try:
        value = json.loads(data, parse_int=_bounded_int, parse_constant=_no_constant)
    except InvalidBody:
        raise
    except RecursionError:
        raise InvalidBody(f"JSON nested deeper than {MAX_JSON_DEPTH} levels") from None
    except ValueError as exc:
        raise InvalidBody(f"Invalid JSON: {exc}") from None
    _check_tree(value)
    return value


def _no_constant(name: str) -> None:
    raise InvalidBody(f"{name} is not a JSON number")


class JSONProvider(DefaultJSONProvider):
    """The app's JSON: bodies are read through parse_json."""

    def loads(self, s: str | bytes, **kwargs: Any) -> Any:
        return parse_json(s)


class CloudSimRequest(Request):
    """A request whose body is bounded in size and in form parts, and whose JSON is checked."""

    max_content_length = MAX_BODY_BYTES
    max_form_memory_size = MAX_BODY_BYTES
    max_form_parts = MAX_FORM_PARTS

    def on_json_loading_failed(self, e: ValueError | None) -> Any:
        if isinstance(e, InvalidBody):
            raise BadRequest(str(e))
        raise BadRequest("Invalid JSON: the body could not be parsed")


class Int(fields.Integer):
    """The API's integer: within [minimum, maximum] (by default the database's range)."""

    def __init__(
        self, *, minimum: int = -INT32_MAX - 1, maximum: int = INT32_MAX, **kwargs: Any
    ) -> None:
        validators = [validate.Range(min=minimum, max=maximum), *kwargs.pop("validate", [])]
        super().__init__(validate=validators, **kwargs)


def Id(**kwargs: Any) -> Int:
    """Return the field of a reference to a row: a positive 32-bit integer."""
    return Int(minimum=1, **kwargs)


class BoundedIntegerField(IntegerField):
    """The forms' integer: refused unless within [minimum, maximum]."""

    def __init__(
        self,
        label: str | None = None,
        validators: list[Any] | None = None,
        *,
        minimum: int = -INT32_MAX - 1,
        maximum: int = INT32_MAX,
        **kwargs: Any,
    ) -> None:
        bound = NumberRange(min=minimum, max=maximum)
        super().__init__(label, [*(validators or []), bound], **kwargs)

    def process_formdata(self, valuelist: list[Any]) -> None:
        # int() of a thousands-digit string is slow and then overflows the database: refuse early.
        if valuelist and len(str(valuelist[0]).strip()) > 20:
            self.data = None
            raise ValueError(self.gettext("Not a valid integer value."))
        super().process_formdata(valuelist)


def query_int(name: str, default: int, minimum: int = 0, maximum: int = INT32_MAX) -> int:
    """Return a page's integer query parameter, clamped into range; junk means the default."""
    raw = request.args.get(name, "")
    if not raw or len(raw) > 20:
        return default
    try:
        return min(max(int(raw), minimum), maximum)
    except ValueError:
        return default


def as_id(text: str) -> int | None:
    """Return text as a row id the database can hold (a command's argument), else None."""
    if not text.isascii() or not text.isdigit() or len(text) > 10 or int(text) > INT32_MAX:
        return None
    return int(text)


def query_id(name: str) -> int | None:
    """Return a page's query parameter naming a row, None when absent; 400 when not an id."""
    raw = request.args.get(name)
    if raw is None:
        return None
    if (value := as_id(raw)) is None:
        raise BadRequest(f"{name} must be a positive whole number below {INT32_MAX + 1}")
    return value


def uploaded_text(upload: object, pasted: str | None, limit: int, what: str) -> str:
    """Return a form's uploaded file as text, else its pasted text; refuse either beyond limit
    bytes (a file is never cut short at the limit and then parsed)."""
    if isinstance(upload, FileStorage) and upload.filename:
        raw = upload.read(limit + 1)
    else:
        raw = (pasted or "").encode()
    if len(raw) > limit:
        raise InvalidInput(f"{what} is at most {limit // 1024} KiB")
    return raw.decode("utf-8", errors="replace")


def init_inputs(app: Flask) -> None:
    """Bound every route's ids and parse every body through this module (before any route)."""
    app.url_map.converters["int"] = IdConverter
    app.request_class = CloudSimRequest
    app.json_provider_class = JSONProvider
    app.json = JSONProvider(app)
    app.config["MAX_CONTENT_LENGTH"] = MAX_BODY_BYTES


class When(fields.AwareDateTime):
    """An ISO 8601 time with a zone, read as UTC (the zone it is stored and compared in)."""

    def _deserialize(self, value: Any, attr: str | None, data: Any, **kwargs: Any) -> datetime:
        when = super()._deserialize(value, attr, data, **kwargs)
        try:
            return when.astimezone(UTC)
        except OverflowError:  # 0001-01-01 at +05:00 is before year 1 in UTC: no 5xx later
            raise ValidationError("a time UTC can hold (years 1 to 9999)") from None
