"""File downloads, for the pages and the API alike."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from flask import Response


def attachment(
    body: bytes | str | Iterable[bytes],
    filename: str,
    mimetype: str = "application/zip",
    *,
    private: bool = False,
    headers: Mapping[str, str] | None = None,
) -> Response:
    """Return a download of body as filename; private ones (keys) are never cached."""
    headers = dict(headers or {})
    headers["Content-Disposition"] = f'attachment; filename="{filename}"'
    if private:
        headers["Cache-Control"] = "no-store"
    return Response(body, mimetype=mimetype, headers=headers)
