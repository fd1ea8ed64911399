"""The EC2 provider's settings (stored encrypted by CloudSim): checked, then driver arguments."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any
from urllib.parse import urlsplit

from provisioners.providers.errors import SettingsError

FIELDS = ("access_key", "secret_key", "region", "image", "sizes", "endpoint")
REQUIRED = ("access_key", "secret_key", "region", "image")


def check(settings: Mapping[str, Any]) -> None:
    """Refuse settings that miss a field, have an unknown one or a malformed endpoint."""
    missing = [key for key in REQUIRED if not settings.get(key)]
    if missing:
        raise SettingsError(f"ec2 needs {', '.join(missing)}")
    unknown = sorted(set(settings) - set(FIELDS))
    if unknown:
        raise SettingsError(f"unknown ec2 settings: {', '.join(unknown)}")
    _endpoint(settings.get("endpoint"))


def driver_arguments(settings: Mapping[str, Any]) -> dict[str, Any]:
    """Return CloudSimEC2NodeDriver's arguments for checked settings."""
    return {
        "key": settings["access_key"],
        "secret": settings["secret_key"],
        "region": settings["region"],
        **_endpoint(settings.get("endpoint")),
    }


def _endpoint(url: str | None) -> dict[str, Any]:
    """Turn an endpoint URL (an EC2-compatible API such as a test server) into driver options."""
    if not url:
        return {}
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise SettingsError(f"endpoint must be an http(s) URL, got {url!r}")
    return {"host": parts.hostname, "port": parts.port, "secure": parts.scheme == "https"}
