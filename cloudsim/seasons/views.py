"""The season's phases page: every rule of every phase; officers schedule and reveal here."""

from __future__ import annotations

from flask import Blueprint, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.errors import NotFound
from cloudsim.extensions import db
from cloudsim.models import Phase, Role
from cloudsim.seasons import service

bp = Blueprint("seasons", __name__)


def _phase(phase_id: int) -> Phase:
    phase = db.session.get(Phase, phase_id)
    if phase is None:
        raise NotFound.of("phase", phase_id)
    return phase


@bp.route("/phases")
@login_required
def phases() -> ResponseReturnValue:
    return render_template(
        "seasons/phases.html",
        phases=service.list_phases(),
        limits=[(key.removeprefix("max_runs_").replace("_", " "), key) for key in service.LIMITS],
        confirm=ConfirmForm(),
    )


@bp.route("/phases/<int:phase_id>/schedule", methods=["POST"])
@role_required(Role.OFFICER)
def schedule_phase(phase_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("seasons.phases")), 400
    phase = _phase(phase_id)
    created = service.schedule_phase(current_user, phase)
    flash(f"{phase.name}: {len(created)} new task(s).", "info")
    return redirect(url_for("seasons.phases"))


@bp.route("/phases/<int:phase_id>/reveal", methods=["POST"])
@role_required(Role.OFFICER)
def reveal(phase_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("seasons.phases")), 400
    phase = service.reveal(current_user, _phase(phase_id))
    flash(f"The scores of {phase.name} are shown to the teams.", "info")
    return redirect(url_for("seasons.phases"))
