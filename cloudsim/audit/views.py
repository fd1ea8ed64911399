"""The audit log page."""

from __future__ import annotations

from flask import Blueprint, render_template, request
from flask.typing import ResponseReturnValue
from flask_login import current_user

from cloudsim.audit.service import visible_events
from cloudsim.auth.policy import role_required
from cloudsim.extensions import db
from cloudsim.models import Role
from cloudsim.web.inputs import query_int

bp = Blueprint("audit", __name__)
PAGE_SIZE = 100


@bp.route("/audit")
@role_required(Role.OFFICER)
def index() -> ResponseReturnValue:
    page = query_int("page", 1, minimum=1)
    action = request.args.get("action") or None
    events = db.paginate(
        visible_events(current_user, action=action),
        page=page,
        per_page=PAGE_SIZE,
        error_out=False,
    )
    return render_template("audit/index.html", events=events, action=action)
