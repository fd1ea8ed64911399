"""The 3D viewer's page and the JSON it loads: the scene, replay frames, live frames."""

from __future__ import annotations

from typing import Any

from flask import Blueprint, Response, current_app, jsonify, render_template
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from webargs.flaskparser import use_args

from cloudsim.competition.views import bandwidth_plots_of
from cloudsim.config import Config
from cloudsim.viewer import live, service
from cloudsim.viewer.schemas import FramesQuery, LiveQuery

bp = Blueprint("viewer", __name__)


@bp.route("/runs/<int:run_id>/view")
@login_required
def view(run_id: int) -> ResponseReturnValue:
    run, mode = service.viewable_run(current_user, run_id)
    config: Config = current_app.config["CLOUDSIM"]
    return render_template(
        "viewer/view.html",
        run=run,
        mode=mode,
        delay_ms=config.viewer_live_delay_ms,
        poll_ms=config.viewer_poll_ms,
        bandwidth_plots=bandwidth_plots_of(run) if mode == "replay" else [],
    )


@bp.route("/runs/<int:run_id>/view/scene")
@login_required
def scene(run_id: int) -> ResponseReturnValue:
    return jsonify(service.scene_answer(current_user, run_id, current_app.config["CLOUDSIM"]))


@bp.route("/runs/<int:run_id>/view/frames")
@login_required
@use_args(FramesQuery(), location="query")
def frames(query: dict[str, float], run_id: int) -> ResponseReturnValue:
    config: Config = current_app.config["CLOUDSIM"]
    frames = service.replay_frames(current_user, run_id, query["start"], query["seconds"], config)
    return jsonify(frames)


@bp.route("/runs/<int:run_id>/view/live")
@login_required
@use_args(LiveQuery(), location="query")
def live_frames(query: dict[str, Any], run_id: int) -> ResponseReturnValue:
    config: Config = current_app.config["CLOUDSIM"]
    body = live.live_answer(current_user, run_id, query["after"], query["viewer"], config)
    return Response(body, mimetype="application/json")
