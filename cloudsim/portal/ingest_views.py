"""Pages of the portal's integrity side: refused uploads (officers), an officer's review of a
run, and the review form on the run page."""

from __future__ import annotations

from flask import Blueprint, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from flask_wtf import FlaskForm
from wtforms import BooleanField, TextAreaField
from wtforms.validators import Length, Optional

from cloudsim.auth.policy import role_required
from cloudsim.errors import Conflict, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Role, Run
from cloudsim.portal import review
from cloudsim.web.inputs import query_int

bp = Blueprint("portal_ingest", __name__)
PAGE = 50


class ReviewForm(FlaskForm):
    """An officer's note on a run, and whether it counts."""

    note = TextAreaField("Note", validators=[Optional(), Length(max=review.MAX_NOTE)])
    invalidated = BooleanField("Invalidated (does not count in the ranking)")
    accepted = BooleanField("Accept this run held for review (it is ranked again)")
    reason = TextAreaField(
        "Why invalidated, or accepted", validators=[Optional(), Length(max=review.MAX_NOTE)]
    )


@bp.app_template_global()
def review_form(run: Run) -> ReviewForm:
    """Return the review form filled with the run's current note and invalidation."""
    return ReviewForm(
        formdata=None,
        note=run.officer_note or "",
        invalidated=run.invalidated_at is not None,
        reason=run.invalid_reason or "",
    )


@bp.route("/portal/refusals")
@role_required(Role.OFFICER)
def refusals() -> ResponseReturnValue:
    page = db.paginate(
        review.refusals(current_user),
        page=query_int("page", 1, minimum=1),
        per_page=PAGE,
        error_out=False,
    )
    return render_template("portal/refusals.html", page=page)


@bp.post("/runs/<int:run_id>/review")
@login_required
def review_run(run_id: int) -> ResponseReturnValue:
    form = ReviewForm()
    if not form.validate_on_submit():
        errors = "; ".join(e for field in form.errors.values() for e in field)
        flash(errors or "The review was not understood.", "error")
        return redirect(url_for("competition.run", run_id=run_id))
    try:
        review.review_run(
            current_user,
            run_id,
            note=form.note.data,
            invalidated=bool(form.invalidated.data),
            reason=form.reason.data,
            accepted=bool(form.accepted.data),
        )
    except (InvalidInput, Conflict) as exc:
        db.session.rollback()
        flash(str(exc), "error")
        return redirect(url_for("competition.run", run_id=run_id))
    flash("Review saved.", "info")
    return redirect(url_for("competition.run", run_id=run_id))
