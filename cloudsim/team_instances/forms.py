"""The forms admins deploy and assign team instances with."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import IntegerField, SelectChoice, SelectField, StringField
from wtforms.validators import DataRequired, Length, NumberRange

from cloudsim.models import Team
from cloudsim.providers.service import PROVIDERS
from constellations.definition import available_kinds


def _team_choices(teams: list[Team], empty: str) -> list[SelectChoice]:
    return [SelectChoice("", empty)] + [SelectChoice(str(t.id), t.name) for t in teams]


class DeployForm(FlaskForm):
    """Name, provider, team (or a number of spares) of new team instances."""

    name = StringField("Name", validators=[DataRequired(), Length(max=21)])
    provider = SelectField("Provider")
    team = SelectField("Team")
    count = IntegerField("How many", default=1, validators=[NumberRange(min=1, max=50)])

    def offer(self, teams: list[Team]) -> DeployForm:
        """Fill the choices."""
        self.provider.choices = [SelectChoice(p) for p in PROVIDERS]
        self.team.choices = _team_choices(teams, "— a spare, assigned later —")
        return self

    def team_id(self) -> int | None:
        """Return the chosen team id, or None."""
        return int(self.team.data) if self.team.data else None


class AssignForm(FlaskForm):
    """The team a spare instance goes to."""

    team = SelectField("Team", validators=[DataRequired()])

    def offer(self, teams: list[Team]) -> AssignForm:
        """Fill the choices."""
        self.team.choices = _team_choices(teams, "— choose —")
        return self


class LaunchThroughForm(FlaskForm):
    """The kind and provider of every team's constellation, launched through its instance."""

    kind = SelectField("Kind", default="vrc")
    provider = SelectField("Provider", default="servers")

    def offer(self) -> LaunchThroughForm:
        """Fill the choices."""
        self.kind.choices = [SelectChoice(k) for k in available_kinds() if k != "cloudsim"]
        self.provider.choices = [SelectChoice(p) for p in PROVIDERS]
        return self
