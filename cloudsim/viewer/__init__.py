"""See a run in 3D: live for officers (relayed through CloudSim), replay for the run's team."""

from __future__ import annotations

from flask import Flask


def init_app(app: Flask) -> None:
    """Register the viewer's pages and its relay job."""
    from cloudsim.viewer import live  # noqa: F401  (registers the viewer.relay job kind)
    from cloudsim.viewer.views import bp

    app.register_blueprint(bp)
