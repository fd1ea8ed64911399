"""Jinja2 templates, shipped as package data: web/ (the pages), machines/ (files for machines)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def folder(name: str) -> Path:
    """Return the installed folder of one template set ("web" or "machines")."""
    # Wheels install unzipped, so the resource is a real folder Jinja2 and Flask can read.
    return Path(str(resources.files(__name__).joinpath(name)))
