"""See a run in 3D: live for officers (relayed through CloudSim), replay for the run's team."""

from __future__ import annotations

from flask import Flask
from flask_smorest import Api

from cloudsim.api import API_PREFIX
from cloudsim.extensions import csrf


def init_app(app: Flask, api: Api) -> None:
    """Register the viewer's pages, its API and its relay job."""
    from cloudsim.viewer import live  # noqa: F401  (registers the viewer.relay job kind)
    from cloudsim.viewer.api import blp
    from cloudsim.viewer.views import bp

    app.register_blueprint(bp)
    csrf.exempt(blp)
    api.register_blueprint(blp, url_prefix=API_PREFIX)
