"""The forms admins deploy and assign team instances with."""

from __future__ import annotations

from typing import Any

from flask_wtf import FlaskForm
from flask_wtf.file import FileField
from wtforms import (
    IntegerField,
    PasswordField,
    SelectChoice,
    SelectField,
    StringField,
    TextAreaField,
)
from wtforms.validators import DataRequired, Length, NumberRange, Optional

from cloudsim.errors import InvalidInput
from cloudsim.models import Team
from cloudsim.providers.service import PROVIDERS, ec2_settings, servers_settings
from cloudsim.web.inputs import uploaded_text
from constellations.definition import available_kinds

MAX_INVENTORY_BYTES = 1 << 20  # a few hundred servers with their keys


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

    # own ids: the deploy form on the same page has a `provider` too (labels find their field)
    kind = SelectField("Kind", default="vrc", id="launch-kind")
    provider = SelectField("Provider", default="servers", id="launch-provider")

    def offer(self) -> LaunchThroughForm:
        """Fill the choices."""
        self.kind.choices = [SelectChoice(k) for k in available_kinds() if k != "cloudsim"]
        self.provider.choices = [SelectChoice(p) for p in PROVIDERS]
        return self


class ProviderSettingsForm(FlaskForm):
    """The provider settings an instance is handed at launch: for `servers` an inventory (file
    or pasted YAML), for `ec2` the fields `cloudsim provider configure ec2` takes."""

    provider = SelectField("Provider", default="servers")
    inventory_file = FileField("servers: inventory file (YAML)")
    inventory_text = TextAreaField(
        "…or the inventory itself", validators=[Length(max=MAX_INVENTORY_BYTES)]
    )
    region = StringField("ec2: region", validators=[Optional(), Length(max=64)])
    access_key = StringField("ec2: access key id", validators=[Optional(), Length(max=128)])
    secret_key = PasswordField("ec2: secret access key", validators=[Optional(), Length(max=256)])
    image = StringField("ec2: machine image (AMI)", validators=[Optional(), Length(max=128)])
    sizes = TextAreaField(
        "ec2: instance type per logical size, one LOGICAL=TYPE a line",
        validators=[Optional(), Length(max=4096)],
    )
    endpoint = StringField(
        "ec2: API URL instead of AWS's", validators=[Optional(), Length(max=256)]
    )

    def offer(self) -> ProviderSettingsForm:
        """Fill the choices: the providers that take settings."""
        self.provider.choices = [SelectChoice(p) for p in PROVIDERS if p != "local"]
        return self

    def settings(self) -> dict[str, Any]:
        """Return the settings as the API takes them (checked by the service, not here)."""
        if self.provider.data == "ec2":
            return self._ec2()
        text = uploaded_text(
            self.inventory_file.data,
            self.inventory_text.data,
            MAX_INVENTORY_BYTES,
            "a servers inventory",
        )
        if not text.strip():
            raise InvalidInput("choose an inventory file or paste the inventory")
        return servers_settings(text, "servers inventory")

    def _ec2(self) -> dict[str, Any]:
        return ec2_settings(
            access_key=self.access_key.data or "",
            secret_key=self.secret_key.data or "",
            region=self.region.data or "",
            image=self.image.data or "",
            sizes=(self.sizes.data or "").splitlines(),
            endpoint=self.endpoint.data,
        )
