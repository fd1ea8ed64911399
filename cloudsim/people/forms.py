"""Forms for managing teams and users."""

from __future__ import annotations

from flask_wtf import FlaskForm
from wtforms import BooleanField, PasswordField, SelectChoice, SelectField, StringField
from wtforms.validators import DataRequired, InputRequired, Length, Optional

from cloudsim.models import Role, Team

NO_TEAM = ""


class TeamForm(FlaskForm):
    """A team's name."""

    name = StringField("Team name", validators=[DataRequired(), Length(max=80)])


class UserForm(FlaskForm):
    """Create or edit a user; officers only see the `user` role."""

    # InputRequired: a submission without the (hidden, when editing) e-mail is no form of ours;
    # otherwise an empty POST would save the user with "active" unticked.
    email = StringField("E-mail", validators=[InputRequired(), Length(max=254)])
    name = StringField("Name", validators=[Optional(), Length(max=120)])
    role = SelectField("Role", choices=[SelectChoice(r.value) for r in Role])
    team = SelectField("Team", choices=[])
    password = PasswordField(
        "Password (leave empty to generate one)", validators=[Optional(), Length(min=10, max=256)]
    )
    active = BooleanField("Active", default=True)

    def offer(self, teams: list[Team], can_manage_staff: bool) -> UserForm:
        """Fill the choices with the teams and the roles this actor may assign."""
        self.team.choices = [SelectChoice(NO_TEAM, "— none (officers and admins) —")] + [
            SelectChoice(str(t.id), t.name) for t in teams
        ]
        if not can_manage_staff:
            self.role.choices = [SelectChoice(Role.USER.value)]
        return self

    def team_id(self) -> int | None:
        """Return the chosen team id, or None."""
        return int(self.team.data) if self.team.data else None
