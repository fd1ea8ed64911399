"""Providers: where constellations run, and their settings (`cloudsim provider`)."""

from __future__ import annotations

import click
from flask import Flask


def init_app(app: Flask) -> None:
    """Register this feature's API with the app."""
    from cloudsim.api import register_api
    from cloudsim.providers import api

    register_api(app, api.blp)


def init_cli(cli: click.Group) -> None:
    """Add this feature's commands to `cloudsim`."""
    from cloudsim.providers.cli import provider

    cli.add_command(provider)
