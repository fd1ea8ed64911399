"""The features CloudSim is made of: each wires itself to Flask, the API, Celery and the CLI.

A feature is a package under `cloudsim/` with `init_app(app)` (pages, API blueprint, job
bodies, periodic tasks) and `init_cli(cli)` (its `cloudsim` commands; separate because the
command line exists before, and often without, an app).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Protocol, cast

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup

# The order is the order of the API's OpenAPI sections.
FEATURES = (
    "cloudsim.auth",
    "cloudsim.dashboard",
    "cloudsim.people",
    "cloudsim.jobs",
    "cloudsim.audit",
    "cloudsim.launched_constellations",
    "cloudsim.providers",
    "cloudsim.competition",
    "cloudsim.seasons",
    "cloudsim.viewer",
    "cloudsim.team_instances",
    "cloudsim.portal",
    "cloudsim.verification",
    "cloudsim.worlds",
    "cloudsim.monitoring",
    "cloudsim.notifications",
)


class Feature(Protocol):
    """What every feature package provides."""

    def init_app(self, app: Flask) -> None: ...

    def init_cli(self, cli: LazyGroup) -> None: ...


def features() -> list[Feature]:
    """Import every feature package (cheap: their hooks import the rest lazily)."""
    return [cast(Feature, import_module(name)) for name in FEATURES]
