"""Pages for constellations: the list, launching, one constellation live, its SSH bundle."""

from __future__ import annotations

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

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.progress import step_since
from cloudsim.jobs.views import job_summary
from cloudsim.launched_constellations import access, service, vpn
from cloudsim.launched_constellations.capacity import describe, room
from cloudsim.launched_constellations.forms import LaunchForm
from cloudsim.launched_constellations.progress import last_heard
from cloudsim.models import Role
from cloudsim.people.service import visible_teams
from cloudsim.web.downloads import attachment
from cloudsim.web.inputs import query_id, query_int
from constellations.plans.base import member_account_name

bp = Blueprint("constellations", __name__)


@bp.route("/constellations")
@login_required
def index() -> ResponseReturnValue:
    form = LaunchForm().offer(visible_teams(current_user))
    return _index(form), 200


def _index(form: LaunchForm) -> str:
    """Render the list with the launch form (and, for admins, the local provider's room)."""
    constellations = db.session.scalars(service.visible_constellations(current_user)).all()
    local_room = None
    if current_user.has_role(Role.ADMIN):
        local_room = describe(room("local", current_app.config["CLOUDSIM"]))
    return render_template(
        "constellations/index.html", constellations=constellations, form=form, room=local_room
    )


@bp.route("/constellations", methods=["POST"])
@role_required(Role.ADMIN)
def launch() -> ResponseReturnValue:
    form = LaunchForm().offer(visible_teams(current_user))
    status = 400
    if form.validate_on_submit():
        try:
            constellation, _ = service.launch(
                current_user,
                name=form.name.data,
                kind=form.kind.data,
                provider=form.provider.data,
                team_id=form.team_id(),
            )
        except CloudSimError as exc:
            db.session.rollback()
            form.form_errors.append(str(exc))
            status = exc.status
        else:
            flash(f"Launching {constellation.name}.", "info")
            return redirect(url_for("constellations.show", ref=constellation.id))
    return _index(form), status


@bp.route("/constellations/<int:ref>")
@login_required
def show(ref: int) -> ResponseReturnValue:
    constellation = service.get_constellation(current_user, ref)
    job = service.latest_job(constellation)
    return render_template(
        "constellations/show.html",
        constellation=constellation,
        job=job,
        heard=last_heard(constellation),
        step_since=step_since(job),
        confirm=ConfirmForm(),
        account=access.account_name(current_user, constellation),
        placeholder=access.ACCOUNT_PLACEHOLDER,
        member_account=member_account_name,
        field_computers=access.field_computers(constellation),
        ssh_config=access.ssh_config(constellation, current_user),
    )


@bp.route("/constellations/<int:ref>/status")
@login_required
def status(ref: int) -> ResponseReturnValue:
    """Return the constellation's and its latest job's state, for the page's live updates."""
    constellation = service.get_constellation(current_user, ref)
    job = service.latest_job(constellation)
    heard = last_heard(constellation)
    show_job = job is not None and current_user.has_role(Role.OFFICER)
    return jsonify(
        state=constellation.state.value,
        error=constellation.error,
        error_code=constellation.error_code,
        step=job.stage if job is not None else None,
        step_since=step_since(job),
        machines=[
            {
                "name": m.name,
                "state": m.state.value,
                "private_ip": m.private_ip,
                "public_ip": m.public_ip,
                "heard": heard.get(m.name),
            }
            for m in constellation.machines
        ],
        job=job_summary(job) if show_job and job is not None else None,
    )


@bp.route("/constellations/<int:ref>/terminate", methods=["POST"])
@role_required(Role.ADMIN)
def terminate(ref: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("constellations.show", ref=ref)), 400
    service.terminate(current_user, ref)
    flash("Terminating.", "info")
    return redirect(url_for("constellations.show", ref=ref))


@bp.route("/constellations/<int:ref>/retry", methods=["POST"])
@role_required(Role.ADMIN)
def retry(ref: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("constellations.show", ref=ref)), 400
    service.retry(current_user, ref)
    flash("Launching again.", "info")
    return redirect(url_for("constellations.show", ref=ref))


@bp.route("/constellations/<int:ref>/team-sudo", methods=["POST"])
@role_required(Role.OFFICER)
def team_sudo(ref: int) -> ResponseReturnValue:
    """Let the team's members use sudo on the field computers (?allowed=1), or not (0)."""
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("constellations.show", ref=ref)), 400
    allowed = query_int("allowed", 0, maximum=1) == 1
    service.set_team_sudo(current_user, ref, allowed)
    flash("The team may now use sudo." if allowed else "The team may no longer use sudo.", "info")
    return redirect(url_for("constellations.show", ref=ref))


@bp.route("/constellations/<int:ref>/ssh-bundle")
@role_required(Role.OFFICER)
def ssh_bundle(ref: int) -> ResponseReturnValue:
    filename, data = service.ssh_bundle(current_user, ref)
    return attachment(data, filename, private=True)


@bp.route("/constellations/<int:ref>/vpn-bundle")
@login_required
def vpn_bundle(ref: int) -> ResponseReturnValue:
    """Download a team user's VPN bundle: one's own, or (officers) ?user_id=N's."""
    constellation = service.get_constellation(current_user, ref)
    user_id = query_id("user_id")
    filename, data = vpn.vpn_bundle(current_user, constellation, user_id)
    return attachment(data, filename, private=True)
