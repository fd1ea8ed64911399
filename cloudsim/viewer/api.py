"""The 3D viewer's data for scripts: a run's scene, replay frames and live frames."""

from __future__ import annotations

from typing import Any

from flask import Response, current_app
from flask.views import MethodView

from cloudsim.api.common import Blueprint, caller
from cloudsim.viewer import live, service
from cloudsim.viewer.schemas import FramesQuery, LiveQuery

blp = Blueprint("api_viewer", __name__, description="A run in 3D: scene, replay and live frames")


@blp.route("/runs/<int:run_id>/view/scene")
class Scene(MethodView):
    @blp.response(200)
    def get(self, run_id: int) -> Any:
        """Return the run (and how the caller may view it), its score marks and world shapes."""
        return service.scene_answer(caller(), run_id, current_app.config["CLOUDSIM"])


@blp.route("/runs/<int:run_id>/view/frames")
class Frames(MethodView):
    @blp.arguments(FramesQuery, location="query")
    @blp.response(200)
    def get(self, query: dict[str, float], run_id: int) -> Any:
        """Return a finished run's link poses from `start` for `seconds` (at most 30)."""
        config = current_app.config["CLOUDSIM"]
        return service.replay_frames(caller(), run_id, query["start"], query["seconds"], config)


@blp.route("/runs/<int:run_id>/view/live")
class LiveFrames(MethodView):
    @blp.arguments(LiveQuery, location="query")
    @blp.response(200)
    def get(self, query: dict[str, Any], run_id: int) -> Any:
        """Return a running run's relayed frames newer than `after` (officers; throttled)."""
        config = current_app.config["CLOUDSIM"]
        body = live.live_answer(caller(), run_id, query["after"], query["viewer"], config)
        return Response(body, mimetype="application/json")
