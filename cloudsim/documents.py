"""Read the documents people hand CloudSim (worlds, schedules, inventories) within limits.

Every YAML or JSON document from a person goes through `load_document`: a size cap before
anything is parsed, no nesting deeper than any real document, no YAML aliases (a few lines
of them expand to gigabytes once copied as JSON), and every parser error turned into one
InvalidInput line. Python's own parsers recurse: unchecked, 5,000 nested brackets are a
RecursionError, not a clear answer.
"""

from __future__ import annotations

import json
from typing import Any

import yaml

from cloudsim.errors import InvalidInput

MAX_DEPTH = 32
MAX_DOCUMENT_BYTES = 1024 * 1024


class BoundedLoader(yaml.SafeLoader):
    """YAML's safe loader refusing aliases and nesting deeper than MAX_DEPTH, as it composes."""

    depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise InvalidInput(f"YAML aliases are not accepted (line {event.start_mark.line + 1})")
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise InvalidInput(f"the document is nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


def load_document(
    text: str | bytes,
    what: str,
    *,
    max_bytes: int = MAX_DOCUMENT_BYTES,
    loader: type[BoundedLoader] = BoundedLoader,
    not_parsed: str = "{what} is not JSON or YAML",
) -> Any:
    """Return the data of a JSON or YAML document (JSON is YAML), or raise InvalidInput.

    not_parsed: the message for a syntax error (formatted with what), before the parser's.
    """
    size = len(text) if isinstance(text, bytes) else len(text.encode("utf-8", "surrogatepass"))
    if size > max_bytes:
        raise InvalidInput(f"{what} is larger than {max_bytes // 1024} KiB")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise InvalidInput(f"{what} is not UTF-8 text") from None
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise InvalidInput(f"{what} is not UTF-8 text") from None
    try:
        return yaml.load(text, Loader=loader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0]
        raise InvalidInput(f"{not_parsed.format(what=what)}: {first}") from None
    except (ValueError, OverflowError, RecursionError) as exc:
        # PyYAML's constructors raise these for 2026-02-30 or 5,000-digit numbers
        raise InvalidInput(f"{what} holds a value YAML cannot read: {exc}") from None


def as_json_data(value: Any, what: str) -> Any:
    """Return value as JSON would carry it (dates, sets refused), or raise InvalidInput."""
    try:
        return json.loads(json.dumps(value))
    except (TypeError, ValueError, RecursionError) as exc:
        raise InvalidInput(f"{what} is not a JSON document: {exc}") from None


def check_depth(value: Any, what: str, max_depth: int = MAX_DEPTH) -> None:
    """Refuse data nested deeper than max_depth (checked without recursion)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > max_depth:
            raise InvalidInput(f"{what} is nested deeper than {max_depth} levels")
        if isinstance(item, dict):
            stack.extend((child, depth + 1) for child in item.values())
        elif isinstance(item, list | tuple):
            stack.extend((child, depth + 1) for child in item)
