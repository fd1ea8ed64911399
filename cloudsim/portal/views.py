"""Portal pages: teams' results and logs, the live leaderboard, the VRC's figures, exports."""

from __future__ import annotations

import json
from typing import Any

from csrouter.bandwidth_log import read_bandwidth_log
from flask import Blueprint, current_app, jsonify, render_template
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from sqlalchemy import select

from cloudsim.auth.policy import require_team_access, role_required
from cloudsim.competition import runs as run_service
from cloudsim.competition.api import StandingSchema
from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.models import Artifact, Role, Team
from cloudsim.portal import charts, figures
from cloudsim.portal.results import FIELDS, ResultRow, results, scoring_run_ids, team_cloudsims
from cloudsim.web.downloads import attachment
from cloudsim.web.inputs import query_int

bp = Blueprint("portal", __name__)
CSV = "text/csv"
FIGURE_RUNS_PAGE = 50  # the figures page lists a season's ~450 scoring runs a page at a time


@bp.route("/portal")
@login_required
def index() -> ResponseReturnValue:
    if not current_user.has_role(Role.OFFICER):
        if current_user.team_id is None:
            return render_template("portal/team.html", team=None, rows=[], logs={}, cloudsim=None)
        return _team_page(current_user.team_id)
    rows = results(current_user)
    teams = list(db.session.scalars(select(Team).order_by(Team.name)))
    summary = {team.id: {"runs": 0, "scoring": 0, "checkpoints": 0} for team in teams}
    for row in rows:
        summary[row.team_id]["runs"] += 1
        if row.scoring:
            summary[row.team_id]["scoring"] += 1
            summary[row.team_id]["checkpoints"] += row.score
    return render_template(
        "portal/index.html", teams=teams, summary=summary, cloudsims=team_cloudsims()
    )


@bp.route("/portal/teams/<int:team_id>")
@login_required
def team(team_id: int) -> ResponseReturnValue:
    require_team_access(current_user, team_id, "team", team_id)
    return _team_page(team_id)


def _team_page(team_id: int) -> ResponseReturnValue:
    shown = db.session.get(Team, team_id)
    if shown is None:
        raise NotFound.of("team", team_id)
    rows = results(current_user, team_id)
    logs: dict[int, list[Artifact]] = {}
    found = select(Artifact).where(Artifact.run_id.in_([r.run_id for r in rows]))
    for artifact in db.session.scalars(found.order_by(Artifact.filename)):
        logs.setdefault(artifact.run_id, []).append(artifact)
    return render_template(
        "portal/team.html",
        team=shown,
        rows=rows,
        logs=logs,
        cloudsim=team_cloudsims([team_id]).get(team_id),
    )


@bp.route("/leaderboard")
@login_required
def leaderboard() -> ResponseReturnValue:
    return render_template(
        "portal/leaderboard.html",
        standings=run_service.leaderboard(current_user),
        rank_unverified=current_app.config["CLOUDSIM"].rank_unverified,
    )


@bp.route("/leaderboard/standings")
@login_required
def standings() -> ResponseReturnValue:
    """Return the leaderboard as JSON, for the page's live updates."""
    return jsonify(StandingSchema(many=True).dump(run_service.leaderboard(current_user)))


@bp.route("/portal/figures")
@login_required
def figure_page() -> ResponseReturnValue:
    rows = results(current_user)
    banked = figures.bits_banked(rows)
    used = figures.uplink_against_score(rows)
    page = db.paginate(
        scoring_run_ids(current_user),
        page=query_int("page", 1, minimum=1),
        per_page=FIGURE_RUNS_PAGE,
        error_out=False,
    )
    listed = set(page.items)
    return render_template(
        "portal/figures.html",
        banked=charts.team_lines(
            "Uplink bits banked over scoring runs",
            figures.series_of(banked, key=0, x=1, y=4),
            x_label="scoring run",
            y_label="bits banked (cumulative)",
        ),
        used=charts.scatter_with_caps(
            "Uplink bits used against score",
            [(str(r[0]), int(r[1]), float(r[3]), float(r[5])) for r in used.rows],
            figures.caps_of(used.rows, 4),
            x_label="uplink bits used (log scale); dotted: the caps",
            y_label="score (checkpoints)",
        ),
        runs=[r for r in rows if r.run_id in listed],
        page=page,
    )


@bp.route("/portal/figures/bits-banked.csv")
@login_required
def bits_banked_csv() -> ResponseReturnValue:
    table = figures.bits_banked(results(current_user))
    return attachment(table.csv(), "bits-banked.csv", CSV)


@bp.route("/portal/figures/uplink-score.csv")
@login_required
def uplink_score_csv() -> ResponseReturnValue:
    table = figures.uplink_against_score(results(current_user))
    return attachment(table.csv(), "uplink-score.csv", CSV)


@bp.route("/runs/<int:run_id>/bandwidth.csv")
@login_required
def bandwidth_csv(run_id: int) -> ResponseReturnValue:
    run = run_service.get_run(current_user, run_id)
    log = artifact_for(run, "bandwidth.jsonl")
    if log is None:
        raise NotFound(f"run {run_id} has no bandwidth log")
    store = LogStore(current_app.config["CLOUDSIM"])
    table = figures.bandwidth_history(read_bandwidth_log(store.lines(log.location)))
    return attachment(table.csv(), f"run-{run_id}-bandwidth.csv", CSV)


@bp.route("/portal/results.csv")
@role_required(Role.OFFICER)
def results_csv() -> ResponseReturnValue:
    table = figures.Table(FIELDS, [_csv_row(r) for r in results(current_user)])
    return attachment(table.csv(), "season-results.csv", CSV)


@bp.route("/portal/results.json")
@role_required(Role.OFFICER)
def results_json() -> ResponseReturnValue:
    body = json.dumps([r.exported() for r in results(current_user)], indent=1)
    return attachment(body, "season-results.json", "application/json")


def _csv_row(row: ResultRow) -> tuple[Any, ...]:
    values = row.exported()
    return tuple("" if values[f] is None else values[f] for f in FIELDS)
