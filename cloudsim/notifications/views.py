"""The webhooks page (admins) and the account page's run e-mail choice."""

from __future__ import annotations

from flask import Blueprint, abort, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required

from cloudsim.audit.service import record
from cloudsim.auth.forms import ConfirmForm
from cloudsim.auth.policy import role_required
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Role
from cloudsim.notifications import service
from cloudsim.notifications.forms import RunEmailsForm, WebhookForm
from cloudsim.web.inputs import query_int

bp = Blueprint("notifications", __name__)
PAGE_SIZE = 50


def _page(
    form: WebhookForm, status: int = 200, new_secret: str | None = None
) -> ResponseReturnValue:
    page = query_int("page", 1, minimum=1)
    deliveries = db.paginate(
        service.deliveries(current_user), page=page, per_page=PAGE_SIZE, error_out=False
    )
    return render_template(
        "notifications/webhooks.html",
        form=form,
        confirm=ConfirmForm(),
        webhooks=service.webhooks(current_user),
        deliveries=deliveries,
        new_secret=new_secret,
    ), status


@bp.route("/admin/webhooks")
@role_required(Role.ADMIN)
def webhooks() -> ResponseReturnValue:
    return _page(WebhookForm())


@bp.route("/admin/webhooks", methods=["POST"])
@role_required(Role.ADMIN)
def add_webhook() -> ResponseReturnValue:
    form = WebhookForm()
    if not form.validate_on_submit():
        return _page(form, 400)
    try:
        hook, secret = service.add_webhook(current_user, form.url.data, form.secret.data)
    except CloudSimError as exc:
        db.session.rollback()
        form.url.errors = [str(exc)]
        return _page(form, exc.status)
    record("webhook.add", current_user, target_type="webhook", target_id=hook.id)
    flash(f"Webhook {hook.url} added.", "info")
    # shown once, on this answer only, when it was generated (never stored in a session)
    return _page(WebhookForm(formdata=None), 200, None if form.secret.data else secret)


@bp.route("/admin/webhooks/<int:webhook_id>/delete", methods=["POST"])
@role_required(Role.ADMIN)
def remove_webhook(webhook_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return _page(WebhookForm(), 400)
    service.remove_webhook(current_user, webhook_id)
    record("webhook.remove", current_user, target_type="webhook", target_id=webhook_id)
    flash("Webhook removed.", "info")
    return redirect(url_for("notifications.webhooks"))


@bp.route("/account/run-emails", methods=["POST"])
@login_required
def run_emails() -> ResponseReturnValue:
    form = RunEmailsForm()
    if not form.validate_on_submit():
        abort(400, "The form expired or was not ours; reload the account page and try again.")
    service.set_run_emails(current_user, bool(form.run_emails.data))
    flash("Run e-mails on." if form.run_emails.data else "Run e-mails off.", "info")
    return redirect(url_for("auth.account"))


def run_emails_form() -> RunEmailsForm:
    """Return the account page's form, ticked as the person chose."""
    form = RunEmailsForm(formdata=None)
    form.run_emails.data = service.wants_run_emails(current_user)
    return form
