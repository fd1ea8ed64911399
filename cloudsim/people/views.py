"""Pages for teams and users (officers and admins; team users see their own team)."""

from __future__ import annotations

from flask import Blueprint, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from sqlalchemy import select
from sqlalchemy.orm import selectinload

from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Constellation, Role
from cloudsim.people import service
from cloudsim.people.forms import TeamForm, UserForm
from cloudsim.web.inputs import query_int

bp = Blueprint("people", __name__)
USERS_PAGE = 100  # a season has hundreds of users: the Users page shows them a page at a time


@bp.route("/teams")
@role_required(Role.OFFICER)
def teams() -> ResponseReturnValue:
    return _teams_page(TeamForm())


def _teams_page(form: TeamForm, status: int = 200) -> ResponseReturnValue:
    teams = service.visible_teams(current_user)
    members = service.member_counts(teams)
    return render_template("people/teams.html", teams=teams, members=members, form=form), status


@bp.route("/teams", methods=["POST"])
@role_required(Role.OFFICER)
def create_team() -> ResponseReturnValue:
    form = TeamForm()
    if form.validate_on_submit():
        try:
            team = service.create_team(current_user, form.name.data)
        except CloudSimError as exc:
            db.session.rollback()
            form.name.errors = [str(exc)]
            status = exc.status
        else:
            flash(f"Team {team.name} created.", "info")
            return redirect(url_for("people.team", team_id=team.id))
    else:
        status = 400
    return _teams_page(form, status)


@bp.route("/teams/<int:team_id>")
@login_required
def team(team_id: int) -> ResponseReturnValue:
    team = service.get_team(current_user, team_id)
    return render_template(
        "people/team.html",
        team=team,
        members=service.visible_users(current_user, team.id),
        constellations=db.session.scalars(
            select(Constellation)
            .where(Constellation.team_id == team.id)
            .options(selectinload(Constellation.machines))
            .order_by(Constellation.id.desc())
        ).all(),
        form=TeamForm(name=team.name),
        confirm=ConfirmForm(),
    )


@bp.route("/teams/<int:team_id>/rename", methods=["POST"])
@role_required(Role.OFFICER)
def rename_team(team_id: int) -> ResponseReturnValue:
    form = TeamForm()
    if not form.validate_on_submit():
        flash("Give the team a name.", "error")
        return redirect(url_for("people.team", team_id=team_id)), 400
    service.rename_team(current_user, team_id, form.name.data)
    flash("Team renamed.", "info")
    return redirect(url_for("people.team", team_id=team_id))


@bp.route("/teams/<int:team_id>/delete", methods=["POST"])
@role_required(Role.OFFICER)
def delete_team(team_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("people.team", team_id=team_id)), 400
    service.delete_team(current_user, team_id)
    flash("Team deleted.", "info")
    return redirect(url_for("people.teams"))


def _user_form(**data: object) -> UserForm:
    form = UserForm(**data)
    return form.offer(service.visible_teams(current_user), current_user.has_role(Role.ADMIN))


@bp.route("/users")
@role_required(Role.OFFICER)
def users() -> ResponseReturnValue:
    page = db.paginate(
        service.users_query(current_user),
        page=query_int("page", 1, minimum=1),
        per_page=USERS_PAGE,
        error_out=False,
    )
    return render_template("people/users.html", page=page, users=page.items)


@bp.route("/users/new", methods=["GET", "POST"])
@role_required(Role.OFFICER)
def create_user() -> ResponseReturnValue:
    form = _user_form()
    status = 200
    if form.is_submitted():
        status = 400
        if form.validate():
            try:
                created = service.create_user(
                    current_user,
                    email=form.email.data,
                    role=form.role.data,
                    team_id=form.team_id(),
                    name=form.name.data or "",
                    password=form.password.data or None,
                )
            except CloudSimError as exc:
                form.form_errors.append(str(exc))
                status = exc.status
            else:
                return render_template(
                    "people/user_created.html",
                    user=created.user,
                    password=created.generated_password,
                )
    return render_template("people/user_form.html", form=form, user=None), status


@bp.route("/users/<int:user_id>", methods=["GET", "POST"])
@role_required(Role.OFFICER)
def edit_user(user_id: int) -> ResponseReturnValue:
    user = service.get_user(current_user, user_id)
    # Not obj=user: WTForms would take user.team (a Team) over team= and select no team.
    form = _user_form(
        email=user.email,
        name=user.name,
        role=user.role.value,
        team=str(user.team_id or ""),
        active=user.active,
    )
    status = 200
    if form.is_submitted():
        status = 400
        if form.validate():
            try:
                service.update_user(
                    current_user,
                    user.id,
                    name=form.name.data or "",
                    role=form.role.data,
                    team_id=form.team_id(),
                    active=form.active.data,
                    password=form.password.data or None,
                )
            except CloudSimError as exc:
                db.session.rollback()
                form.form_errors.append(str(exc))
                status = exc.status
            else:
                flash(f"Saved {user.email}.", "info")
                return redirect(url_for("people.users"))
    return render_template(
        "people/user_form.html", form=form, user=user, confirm=ConfirmForm()
    ), status


@bp.route("/users/<int:user_id>/delete", methods=["POST"])
@role_required(Role.OFFICER)
def delete_user(user_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("people.edit_user", user_id=user_id)), 400
    service.delete_user(current_user, user_id)
    flash("User deleted.", "info")
    return redirect(url_for("people.users"))
