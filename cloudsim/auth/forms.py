"""Forms for logging in and for one's own account."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import PasswordField, StringField, TextAreaField
from wtforms.validators import DataRequired, EqualTo, Length


class LoginForm(FlaskForm):
    """E-mail and password."""

    email = StringField("E-mail", validators=[DataRequired(), Length(max=254)])
    password = PasswordField("Password", validators=[DataRequired(), Length(max=256)])


class PasswordForm(FlaskForm):
    """Change one's own password."""

    current = PasswordField("Current password", validators=[DataRequired()])
    new = PasswordField("New password", validators=[DataRequired(), Length(min=10, max=256)])
    confirm = PasswordField(
        "Repeat new password", validators=[EqualTo("new", message="the passwords differ")]
    )


class TokenForm(FlaskForm):
    """Name a new API token."""

    name = StringField("Token name", validators=[DataRequired(), Length(max=80)])


class SshKeyForm(FlaskForm):
    """Add an SSH public key (or leave it empty and ask CloudSim to make one)."""

    name = StringField("Key name (optional)", validators=[Length(max=80)])
    public_key = TextAreaField(
        "Public key (one line: ssh-ed25519 AAAA... you@laptop)", validators=[Length(max=16384)]
    )


class ConfirmForm(FlaskForm):
    """A form with only the CSRF token, for buttons that change something."""
