"""Alembic migrations (env.py, versions/), shipped as package data with CloudSim."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def folder() -> Path:
    """Return the installed folder of the migration scripts (Alembic's script_location)."""
    return Path(str(resources.files(__name__)))
