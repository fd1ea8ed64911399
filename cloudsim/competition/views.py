"""Pages of the competition: tasks (schedule, import, export, start), runs live (the leaderboard
is the portal's)."""

from __future__ import annotations

import threading
from datetime import datetime
from typing import Any

from csrouter.bandwidth_log import read_bandwidth_log
from flask import (
    Blueprint,
    current_app,
    flash,
    jsonify,
    redirect,
    render_template,
    url_for,
)
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from sqlalchemy.orm import selectinload

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.competition import live_view, schedule, season
from cloudsim.competition import runs as run_service
from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.forms import ImportForm, ReviewForm, ScheduleForm
from cloudsim.competition.plots import bandwidth_charts, score_chart
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Role, Run, Task, User
from cloudsim.people.service import visible_teams
from cloudsim.web.downloads import attachment
from cloudsim.web.inputs import query_int

bp = Blueprint("competition", __name__)
# A season holds hundreds of tasks and runs: the pages show them a page at a time.
TASKS_PAGE = 100
RUNS_PAGE = 50
CHARTS_KEPT = 32  # runs whose bandwidth charts a worker keeps (~130 kB each for 30 minutes)
_CHARTS: dict[str, list[Any]] = {}
_CHARTS_LOCK = threading.Lock()


def _tasks_page(form: ScheduleForm, import_form: ImportForm, status: int = 200) -> Any:
    page = db.paginate(
        schedule.visible_tasks(current_user).options(selectinload(Task.runs)),
        page=query_int("page", 1, minimum=1),
        per_page=TASKS_PAGE,
        error_out=False,
    )
    return render_template(
        "competition/tasks.html",
        page=page,
        tasks=page.items,
        open_ids={t.id for t in schedule.open_tasks(current_user)},
        form=form,
        import_form=import_form,
        confirm=ConfirmForm(),
    ), status


@bp.route("/tasks")
@login_required
def tasks() -> ResponseReturnValue:
    return _tasks_page(ScheduleForm().offer(visible_teams(current_user)), ImportForm())


@bp.route("/tasks", methods=["POST"])
@role_required(Role.OFFICER)
def schedule_task() -> ResponseReturnValue:
    form = ScheduleForm().offer(visible_teams(current_user))
    if form.validate_on_submit():
        try:
            spec = schedule.TaskSpec(
                name=form.name.data or "",
                world=form.world.data or "",
                run_config=form.run_config.data or 0,
                window_start=schedule.to_utc(form.window_start.data, form.time_zone.data or ""),
                window_stop=schedule.to_utc(form.window_stop.data, form.time_zone.data or ""),
                timeout_s=form.timeout_s.data or 0,
                latency_ms=form.latency_ms.data or 0,
                uplink_bits=form.uplink_bits.data or 0,
                downlink_bits=form.downlink_bits.data or 0,
                order=form.order.data or 0,
                time_zone=form.time_zone.data or "",
            )
            created = schedule.schedule(current_user, spec, form.team_ids())
        except CloudSimError as exc:
            db.session.rollback()
            form.form_errors.append(str(exc))
            return _tasks_page(form, ImportForm(), exc.status)
        flash(f"Scheduled {created[0].name} for {len(created)} team(s).", "info")
        return redirect(url_for("competition.tasks"))
    return _tasks_page(form, ImportForm(), 400)


@bp.route("/tasks/<int:task_id>/delete", methods=["POST"])
@role_required(Role.OFFICER)
def delete_task(task_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("competition.tasks")), 400
    schedule.delete_task(current_user, task_id)
    flash("Task deleted.", "info")
    return redirect(url_for("competition.tasks"))


@bp.route("/tasks/import", methods=["POST"])
@role_required(Role.OFFICER)
def import_schedule() -> ResponseReturnValue:
    form = ImportForm()
    if form.validate_on_submit():
        try:
            created = season.import_season(current_user, form.text())
        except CloudSimError as exc:
            db.session.rollback()
            form.form_errors.append(str(exc))
            return _tasks_page(ScheduleForm().offer(visible_teams(current_user)), form, exc.status)
        flash(f"Imported the schedule: {len(created)} new task(s).", "info")
        return redirect(url_for("competition.tasks"))
    return _tasks_page(ScheduleForm().offer(visible_teams(current_user)), form, 400)


@bp.route("/tasks/export")
@role_required(Role.OFFICER)
def export_schedule() -> ResponseReturnValue:
    return attachment(season.export_season(current_user), "schedule.yaml", "application/yaml")


@bp.route("/tasks/<int:task_id>/start", methods=["POST"])
@login_required
def start(task_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("competition.tasks")), 400
    run = run_service.start_run(current_user, task_id)
    flash(f"Run {run.id} is starting.", "info")
    return redirect(url_for("competition.run", run_id=run.id))


@bp.route("/runs")
@login_required
def runs() -> ResponseReturnValue:
    page = db.paginate(
        run_service.visible_runs(current_user),
        page=query_int("page", 1, minimum=1),
        per_page=RUNS_PAGE,
        error_out=False,
    )
    return render_template("competition/runs.html", page=page)


@bp.route("/runs/<int:run_id>")
@login_required
def run(run_id: int) -> ResponseReturnValue:
    return _run_page(run_service.get_run(current_user, run_id), ReviewForm())


def _run_page(shown: Run, review: ReviewForm, status: int = 200) -> Any:
    config = current_app.config["CLOUDSIM"]
    figures, _ = live_view.cached(config, shown)
    now = live_view.live_status(config, shown, figures)
    charts = None
    if figures:
        charts = live_view.live_charts(shown, figures, live_view.samples(config, shown))
    return render_template(
        "competition/run.html",
        run=shown,
        now=now,
        score_plot=charts["score"] if charts else _score_plot(shown),
        bandwidth_plots=bandwidth_plots_of(shown) or (charts["bandwidth"] if charts else []),
        bits_left=now["bits_left"],
        caps_spent=now["caps_spent"],
        confirm=ConfirmForm(),
        review=review,
    ), status


@bp.route("/runs/<int:run_id>/settle", methods=["POST"])
@role_required(Role.OFFICER)
def settle(run_id: int) -> ResponseReturnValue:
    shown = run_service.get_run(current_user, run_id)
    form = ReviewForm()
    if not form.validate_on_submit():
        return _run_page(shown, form, 400)
    try:
        run_service.settle_review(
            current_user, run_id, form.decision.data == "accept", form.note.data or ""
        )
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _run_page(run_service.get_run(current_user, run_id), form, exc.status)
    db.session.commit()
    flash(f"Run {run_id} settled.", "info")
    return redirect(url_for("competition.run", run_id=run_id))


def _score_plot(run: Run) -> Any:
    events = [(e.sim_time, e.kind, _score_after(run, e.sim_time)) for e in run.score_events]
    return score_chart(events, run.sim_seconds)


def bandwidth_plots_of(run: Run) -> list[Any]:
    """Return the run's bandwidth charts (none before its bandwidth log is stored)."""
    bandwidth = next((a for a in run.artifacts if a.filename == "bandwidth.jsonl"), None)
    if bandwidth is None:
        return []
    # A stored log never changes under its checksum: chart it once per worker, not per view
    # (the store may be a remote object store, and a 30-minute log is 3,600 lines).
    with _CHARTS_LOCK:
        charts = _CHARTS.pop(bandwidth.sha256, None)
    if charts is None:
        store = LogStore(current_app.config["CLOUDSIM"])
        charts = bandwidth_charts(read_bandwidth_log(store.lines(bandwidth.location)))
    with _CHARTS_LOCK:
        _CHARTS[bandwidth.sha256] = charts  # the most recently viewed last
        while len(_CHARTS) > CHARTS_KEPT:
            _CHARTS.pop(next(iter(_CHARTS)))
    return charts


def _score_after(run: Run, sim_time: float) -> int:
    return sum(e.points for e in run.score_events if e.sim_time <= sim_time)


@bp.route("/runs/<int:run_id>/status")
@login_required
def run_status(run_id: int) -> ResponseReturnValue:
    """Return the run's state and live figures with its charts, for the page's live updates."""
    shown = run_service.get_run(current_user, run_id)
    config = current_app.config["CLOUDSIM"]
    figures, count = live_view.cached(config, shown)
    now = live_view.live_status(config, shown, figures)
    if figures:
        now["charts"] = live_view.charts_html(config, shown, figures, count)
    return jsonify(now)


@bp.route("/runs/<int:run_id>/stop", methods=["POST"])
@login_required
def stop(run_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("competition.run", run_id=run_id)), 400
    run_service.stop_run(current_user, run_id)
    flash("Stopping the run.", "info")
    return redirect(url_for("competition.run", run_id=run_id))


@bp.route("/runs/<int:run_id>/logs/<int:artifact_id>")
@login_required
def download(run_id: int, artifact_id: int) -> ResponseReturnValue:
    return run_service.log_download(current_user, run_id, artifact_id)


@bp.app_template_global("competition_now")
def competition_now(user: User) -> dict[str, Any]:
    """Return what a dashboard shows of the competition: open tasks and live runs."""
    if user.has_role(Role.OFFICER):
        live = db.session.scalars(
            run_service.visible_runs(user).where(Run.state.in_(run_service.LIVE))
        ).all()
        return {"open": schedule.open_tasks(user), "live": None, "live_runs": live}
    if user.team_id is None:
        return {"open": [], "live": None, "live_runs": []}
    live_run = run_service.live_run(user.team_id)
    return {
        "open": schedule.open_tasks(user, user.team_id),
        "live": live_run,
        "live_runs": [live_run] if live_run else [],
    }


@bp.app_template_filter("in_zone")
def in_zone_filter(value: datetime, zone_name: str) -> str:
    """Show a UTC time as wall-clock time in a zone."""
    return schedule.in_zone(value, zone_name).strftime("%Y-%m-%d %H:%M")
