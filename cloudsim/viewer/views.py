"""The 3D viewer's page and the JSON it loads: the scene, replay frames, live frames."""

from __future__ import annotations

import math

from flask import Blueprint, Response, current_app, jsonify, render_template, request
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required

from cloudsim.competition.views import bandwidth_plots_of
from cloudsim.config import Config
from cloudsim.errors import InvalidInput
from cloudsim.viewer import live, service

bp = Blueprint("viewer", __name__)


def _number(name: str, default: float) -> float:
    raw = request.args.get(name)
    if raw is None:
        return default
    try:
        value = float(raw)
    except ValueError:
        raise InvalidInput(f"{name} must be a number") from None
    if not math.isfinite(value):
        raise InvalidInput(f"{name} must be a finite number")
    return value


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
    return jsonify(service.scene_answer(current_user, run_id))


@bp.route("/runs/<int:run_id>/view/frames")
@login_required
def frames(run_id: int) -> ResponseReturnValue:
    config: Config = current_app.config["CLOUDSIM"]
    start, seconds = _number("start", 0.0), _number("seconds", 5.0)
    return jsonify(service.replay_frames(current_user, run_id, start, seconds, config))


@bp.route("/runs/<int:run_id>/view/live")
@login_required
def live_frames(run_id: int) -> ResponseReturnValue:
    config: Config = current_app.config["CLOUDSIM"]
    after, viewer = _number("after", -1.0), request.args.get("viewer", "")
    body = live.live_answer(current_user, run_id, after, viewer, config)
    return Response(body, mimetype="application/json")
