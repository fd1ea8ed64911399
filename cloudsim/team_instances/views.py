"""Pages for team instances: the list with their health, deploying, one instance, assigning."""

from __future__ import annotations

from flask import Blueprint, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.progress import job_step
from cloudsim.models import Role
from cloudsim.people.service import visible_teams
from cloudsim.team_instances import launch, service
from cloudsim.team_instances.forms import (
    AssignForm,
    DeployForm,
    LaunchThroughForm,
    ProviderSettingsForm,
)

bp = Blueprint("team_instances", __name__)


def _index(
    form: DeployForm, status: int = 200, launching: LaunchThroughForm | None = None
) -> ResponseReturnValue:
    instances = db.session.scalars(service.visible_instances(current_user)).all()
    return render_template(
        "team_instances/index.html",
        instances=instances,
        form=form,
        launching=launching or LaunchThroughForm().offer(),
    ), status


@bp.route("/team-instances")
@role_required(Role.ADMIN)
def index() -> ResponseReturnValue:
    return _index(DeployForm().offer(visible_teams(current_user)))


@bp.route("/team-instances", methods=["POST"])
@role_required(Role.ADMIN)
def deploy() -> ResponseReturnValue:
    form = DeployForm().offer(visible_teams(current_user))
    if not form.validate_on_submit():
        return _index(form, 400)
    try:
        deployed = service.deploy(
            current_user,
            name=form.name.data or "",
            provider=form.provider.data,
            team_id=form.team_id(),
            count=form.count.data or 1,
        )
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _index(form, exc.status)
    flash(f"Deploying {', '.join(i.name for i, _ in deployed)}.", "info")
    if len(deployed) == 1:
        return redirect(url_for("team_instances.show", instance_id=deployed[0][0].id))
    return redirect(url_for("team_instances.index"))


@bp.route("/team-instances/launch", methods=["POST"])
@role_required(Role.ADMIN)
def launch_all() -> ResponseReturnValue:
    form = LaunchThroughForm().offer()
    deploy_form = DeployForm().offer(visible_teams(current_user))
    if not form.validate_on_submit():
        return _index(deploy_form, 400, form)
    try:
        summary = launch.launch(current_user, form.kind.data, form.provider.data)
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _index(deploy_form, exc.status, form)
    if not summary:
        flash("No team has an instance yet.", "info")
    for outcome in summary:
        why = f": {outcome.why}" if outcome.why else ""
        category = "error" if outcome.state == "failed" else "info"
        flash(f"{outcome.instance} ({outcome.team}): {outcome.state}{why}", category)
    return redirect(url_for("team_instances.index"))


def _show(
    instance_id: int,
    form: AssignForm,
    status: int = 200,
    settings: ProviderSettingsForm | None = None,
) -> ResponseReturnValue:
    instance = service.get_instance(current_user, instance_id)
    return render_template(
        "team_instances/show.html",
        instance=instance,
        assign=form,
        confirm=ConfirmForm(),
        settings=settings or ProviderSettingsForm().offer(),
        kept=launch.kept_settings(instance.id),
        drift=service.drift_history(current_user, instance),
        step=job_step(service.latest_job(instance)),
    ), status


@bp.route("/team-instances/<int:instance_id>")
@role_required(Role.ADMIN)
def show(instance_id: int) -> ResponseReturnValue:
    return _show(instance_id, AssignForm().offer(visible_teams(current_user)))


@bp.route("/team-instances/<int:instance_id>/provider", methods=["POST"])
@role_required(Role.ADMIN)
def provider_settings(instance_id: int) -> ResponseReturnValue:
    form = ProviderSettingsForm().offer()
    assign = AssignForm().offer(visible_teams(current_user))
    if not form.validate_on_submit():
        return _show(instance_id, assign, 400, form)
    try:
        # the service the API and CLI call: same checks, same audit line
        instance = launch.set_provider_settings(
            current_user, instance_id, form.provider.data, form.settings()
        )
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _show(instance_id, assign, exc.status, form)
    flash(f"{instance.name}: {form.provider.data} settings kept (encrypted).", "info")
    return redirect(url_for("team_instances.show", instance_id=instance_id))


@bp.route("/team-instances/<int:instance_id>/assign", methods=["POST"])
@role_required(Role.ADMIN)
def assign(instance_id: int) -> ResponseReturnValue:
    form = AssignForm().offer(visible_teams(current_user))
    if not form.validate_on_submit():
        return _show(instance_id, form, 400)
    try:
        instance = service.assign(current_user, instance_id, int(form.team.data))
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _show(instance_id, form, exc.status)
    flash(f"{instance.name} now serves {instance.team.name}.", "info")  # type: ignore[union-attr]
    return redirect(url_for("team_instances.show", instance_id=instance_id))


@bp.route("/team-instances/<int:instance_id>/terminate", methods=["POST"])
@role_required(Role.ADMIN)
def terminate(instance_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("team_instances.show", instance_id=instance_id)), 400
    service.terminate(current_user, instance_id)
    flash("Terminating.", "info")
    return redirect(url_for("team_instances.show", instance_id=instance_id))
