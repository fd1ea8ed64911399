"""Log in, log out, and one's own account (password, API tokens, SSH keys)."""

from __future__ import annotations

from urllib.parse import urlsplit

from flask import Blueprint, current_app, flash, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_required
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth import ssh_keys
from cloudsim.auth.forms import ConfirmForm, LoginForm, PasswordForm, SshKeyForm, TokenForm
from cloudsim.auth.master import WAITING_MESSAGE, awaiting_master, is_master_account
from cloudsim.auth.passwords import verify_password
from cloudsim.auth.service import change_own_password
from cloudsim.auth.session import end_session, start_session
from cloudsim.auth.tokens import issue_token, revoke_token
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db, limiter
from cloudsim.models import User, utcnow

bp = Blueprint("auth", __name__)


def _login_limit() -> str:
    return str(current_app.config["CLOUDSIM"].login_limit)


def _account_key() -> str:
    return "login:" + request.form.get("email", "").strip().lower()


def _failed(response: object) -> bool:
    """Only failed attempts count against the limit (a success redirects)."""
    return getattr(response, "status_code", 200) != 302


def _safe_next(target: str | None) -> str:
    """Return a local redirect target only (never another site)."""
    if target and target.startswith("/") and not target.startswith("//"):
        parts = urlsplit(target)
        if not parts.scheme and not parts.netloc:
            return target
    return url_for("dashboard.index")


@bp.route("/login", methods=["GET", "POST"])
@limiter.limit(_login_limit, methods=["POST"], deduct_when=_failed)
@limiter.limit(_login_limit, methods=["POST"], deduct_when=_failed, key_func=_account_key)
def login() -> ResponseReturnValue:
    if current_user.is_authenticated:
        return redirect(url_for("dashboard.index"))
    form = LoginForm()
    if form.validate_on_submit():
        email = form.email.data.strip().lower()
        user = db.session.scalar(select(User).where(User.email == email))
        # Verify even for an unknown e-mail, so that timing does not reveal which accounts exist.
        password_ok = verify_password(user.password_hash if user else None, form.password.data)
        if user is not None and user.active and password_ok:
            if not is_master_account(user) and awaiting_master():
                flash(WAITING_MESSAGE, "error")  # a restarted team instance (auth.master)
                return render_template("auth/login.html", form=form), 503
            start_session(user)
            user.last_login_at = utcnow()
            record("auth.login", user, target_type="user", target_id=user.id, team_id=user.team_id)
            return redirect(_safe_next(request.args.get("next")))
        record("auth.login_failed", None, target_type="user", target_id=None, email=email)
        db.session.commit()  # kept although the answer is a refusal, which commits nothing
        if user is not None and password_ok:
            # Only someone who knows the password learns that the account exists but is off.
            flash(
                "Your account is disabled: ask an officer of the competition to enable it.", "error"
            )
            return render_template("auth/login.html", form=form), 403
        flash("Wrong e-mail or password.", "error")
        return render_template("auth/login.html", form=form), 401
    status = 400 if request.method == "POST" else 200
    return render_template("auth/login.html", form=form), status


@bp.route("/logout", methods=["POST"])
@login_required
def logout() -> ResponseReturnValue:
    if ConfirmForm().validate_on_submit():
        record(
            "auth.logout",
            current_user,
            target_type="user",
            target_id=current_user.id,
            team_id=current_user.team_id,
        )
        end_session()
        flash("You are logged out.", "info")
    return redirect(url_for("auth.login"))


def _account_page(status: int = 200, **forms: object) -> ResponseReturnValue:
    """Render the account page; `forms` replaces the blank forms (with their errors) or adds
    what is shown once (a new token, a generated private key)."""
    context = {
        "password_form": PasswordForm(),
        "token_form": TokenForm(),
        "ssh_form": SshKeyForm(),
        "confirm": ConfirmForm(),
        "new_token": None,
        "new_private_key": None,
        **forms,
    }
    return render_template("auth/account.html", **context), status


@bp.route("/account", methods=["GET"])
@login_required
def account() -> ResponseReturnValue:
    return _account_page()


@bp.route("/account/password", methods=["POST"])
@login_required
def change_password() -> ResponseReturnValue:
    form = PasswordForm()
    status = 400
    if form.validate_on_submit():
        if not verify_password(current_user.password_hash, form.current.data):
            form.current.errors = ["wrong password"]
        else:
            try:
                # Changing a password ends every session, this one included: log in again.
                user = current_user._get_current_object()
                change_own_password(user, form.new.data)
                start_session(user)
                flash("Password changed; other sessions were logged out.", "info")
                return redirect(url_for("auth.account"))
            except CloudSimError as exc:
                form.new.errors = [str(exc)]
                status = exc.status
    return _account_page(status, password_form=form)


@bp.route("/account/tokens", methods=["POST"])
@login_required
def create_token() -> ResponseReturnValue:
    form = TokenForm()
    if form.validate_on_submit():
        try:
            issued = issue_token(current_user, form.name.data)
        except CloudSimError as exc:
            form.name.errors = [str(exc)]
        else:
            return _account_page(new_token=issued.plaintext)
    return _account_page(400, token_form=form)


@bp.route("/account/tokens/<int:token_id>/revoke", methods=["POST"])
@login_required
def revoke(token_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("auth.account")), 400
    revoke_token(current_user, token_id)
    flash("Token revoked.", "info")
    return redirect(url_for("auth.account"))


@bp.route("/account/ssh-keys", methods=["POST"])
@login_required
def add_ssh_key() -> ResponseReturnValue:
    form = SshKeyForm()
    if form.validate_on_submit():
        try:
            if request.form.get("generate"):
                made = ssh_keys.generate_key(current_user, form.name.data or "")
                # the private key is in this page only: CloudSim keeps the public half
                return _account_page(new_private_key=made.private_key)
            key = ssh_keys.add_key(current_user, form.public_key.data or "", form.name.data or "")
        except CloudSimError as exc:
            form.public_key.errors = [str(exc)]
            return _account_page(exc.status, ssh_form=form)
        flash(f"SSH key {key.fingerprint} added.", "info")
        return redirect(url_for("auth.account"))
    return _account_page(400, ssh_form=form)


@bp.route("/account/ssh-keys/<int:key_id>/delete", methods=["POST"])
@login_required
def delete_ssh_key(key_id: int) -> ResponseReturnValue:
    if not ConfirmForm().validate_on_submit():
        return redirect(url_for("auth.account")), 400
    ssh_keys.delete_key(current_user, key_id)
    flash("SSH key removed.", "info")
    return redirect(url_for("auth.account"))
