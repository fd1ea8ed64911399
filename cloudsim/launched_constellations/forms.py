"""The form admins launch constellations with."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import SelectChoice, SelectField, StringField
from wtforms.validators import DataRequired, Length

from cloudsim.models import Team
from cloudsim.providers.service import PROVIDERS
from constellations.definition import available_kinds


class LaunchForm(FlaskForm):
    """Name, kind, provider and team of a new constellation."""

    name = StringField("Name", validators=[DataRequired(), Length(max=24)])
    kind = SelectField("Kind", default="vrc")  # what most launches are: a team's four machines
    provider = SelectField("Provider")
    team = SelectField("Team")

    def offer(self, teams: list[Team]) -> LaunchForm:
        """Fill the choices."""
        self.kind.choices = [SelectChoice(k) for k in available_kinds()]
        self.provider.choices = [SelectChoice(p) for p in PROVIDERS]
        self.team.choices = [SelectChoice("", "— no team —")] + [
            SelectChoice(str(t.id), t.name) for t in teams
        ]
        return self

    def team_id(self) -> int | None:
        """Return the chosen team id, or None."""
        return int(self.team.data) if self.team.data else None
