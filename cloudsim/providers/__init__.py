"""Providers: where constellations run, and their settings (`cloudsim provider`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register this feature's API with the app."""
    from cloudsim.api import register_api
    from cloudsim.providers import api

    register_api(app, api.blp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    cli.add_lazy_command(
        "provider",
        "cloudsim.providers.cli:provider",
        "Configure and list the providers constellations can be launched on.",
    )
