"""Forms of the notifications pages."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import BooleanField, StringField
from wtforms.validators import DataRequired, Length, Optional


class WebhookForm(FlaskForm):
    """A new webhook: its URL and, optionally, its signing secret."""

    url = StringField("URL", validators=[DataRequired(), Length(max=500)])
    secret = StringField(
        "Secret (16 to 200 characters; leave empty to generate one)",
        validators=[Optional(), Length(min=16, max=200)],
    )


class RunEmailsForm(FlaskForm):
    """Whether one wants run e-mails."""

    run_emails = BooleanField("E-mail me when my team's runs start, end, fail or need review")
