"""The dashboard: what each role needs first."""

from __future__ import annotations

from flask import Blueprint, render_template
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from sqlalchemy import func, select
from sqlalchemy.orm import selectinload

from cloudsim.extensions import db
from cloudsim.jobs.service import visible_jobs
from cloudsim.launched_constellations.service import visible_constellations
from cloudsim.models import Constellation, Role, Run, Task, Team, User, utcnow
from cloudsim.people.service import member_counts, visible_teams

bp = Blueprint("dashboard", __name__)
RECENT = 10


@bp.route("/")
@login_required
def index() -> ResponseReturnValue:
    if current_user.has_role(Role.ADMIN):
        return render_template(
            "dashboard/admin.html",
            constellations=db.session.scalars(
                select(Constellation)
                .options(selectinload(Constellation.machines), selectinload(Constellation.team))
                .order_by(Constellation.created_at.desc())
                .limit(50)
            ).all(),
            jobs=db.session.scalars(visible_jobs(current_user).limit(RECENT)).all(),
            counts=_counts(),
        )
    if current_user.has_role(Role.OFFICER):
        teams = visible_teams(current_user)
        return render_template(
            "dashboard/officer.html",
            teams=teams,
            members=member_counts(teams),
            counts=_counts(),
            tasks=db.session.scalars(
                select(Task)
                .where(Task.window_stop > utcnow())
                .order_by(Task.window_start)
                .limit(RECENT)
            ).all(),
        )
    team = current_user.team
    return render_template(
        "dashboard/user.html",
        team=team,
        constellations=db.session.scalars(visible_constellations(current_user)).all(),
        runs=db.session.scalars(
            select(Run)
            .options(selectinload(Run.task))
            .where(Run.team_id == current_user.team_id)
            .order_by(Run.started_at.desc())
            .limit(RECENT)
        ).all(),
    )


def _counts() -> dict[str, int]:
    return {
        "teams": db.session.scalar(select(func.count(Team.id))) or 0,
        "users": db.session.scalar(select(func.count(User.id))) or 0,
        "constellations": db.session.scalar(select(func.count(Constellation.id))) or 0,
    }
