"""See a run in 3D: live for officers (relayed through CloudSim), replay for the run's team."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from flask import Flask

    from cloudsim.cli.lazy import LazyGroup


def init_app(app: Flask) -> None:
    """Register the viewer's pages, its API and its relay job."""
    from cloudsim.api import register_api
    from cloudsim.viewer import live  # noqa: F401  (registers the viewer.relay job kind)
    from cloudsim.viewer.api import blp
    from cloudsim.viewer.views import bp

    app.register_blueprint(bp)
    register_api(app, blp)


def init_cli(cli: LazyGroup) -> None:
    """Add this feature's commands to `cloudsim`."""
    del cli  # no commands of its own
