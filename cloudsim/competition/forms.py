"""Forms officers schedule and import tasks with."""

from __future__ import annotations

from flask_wtf import FlaskForm
from flask_wtf.file import FileField
from wtforms import (
    DateTimeLocalField,
    SelectChoice,
    SelectField,
    StringField,
    TextAreaField,
)
from wtforms.validators import DataRequired, InputRequired, Length, NumberRange, Optional

from cloudsim.competition.schedule import (
    DEFAULT_DOWNLINK_BITS,
    DEFAULT_LATENCY_MS,
    DEFAULT_TIMEOUT_S,
    DEFAULT_UPLINK_BITS,
)
from cloudsim.models import Team
from cloudsim.web.inputs import INT64_MAX, BoundedIntegerField
from cloudsim.worlds.service import worlds

ALL_TEAMS = "all"
LOCAL_FORMAT = ["%Y-%m-%dT%H:%M", "%Y-%m-%dT%H:%M:%S"]


class ScheduleForm(FlaskForm):
    """A task for one team or every team, its window in the officer's time zone."""

    name = StringField("Name", validators=[DataRequired(), Length(max=120)])
    team = SelectField("Team")
    world = SelectField("World")
    run_config = BoundedIntegerField("Run configuration", default=1, validators=[InputRequired()])
    time_zone = StringField("Time zone", default="UTC", validators=[DataRequired()])
    window_start = DateTimeLocalField(
        "Window opens", format=LOCAL_FORMAT, validators=[InputRequired()]
    )
    window_stop = DateTimeLocalField(
        "Window closes", format=LOCAL_FORMAT, validators=[InputRequired()]
    )
    timeout_s = BoundedIntegerField(
        "Timeout (s)", default=DEFAULT_TIMEOUT_S, validators=[InputRequired(), NumberRange(1)]
    )
    latency_ms = BoundedIntegerField(
        "Latency each way (ms)", default=DEFAULT_LATENCY_MS, validators=[InputRequired()]
    )
    uplink_bits = BoundedIntegerField(
        "Uplink cap (bits)",
        default=DEFAULT_UPLINK_BITS,
        validators=[InputRequired()],
        maximum=INT64_MAX,
    )
    downlink_bits = BoundedIntegerField(
        "Downlink cap (bits)",
        default=DEFAULT_DOWNLINK_BITS,
        validators=[InputRequired()],
        maximum=INT64_MAX,
    )
    order = BoundedIntegerField("Order", default=0, validators=[Optional()])

    def offer(self, teams: list[Team]) -> ScheduleForm:
        """Fill the choices."""
        self.team.choices = [SelectChoice(ALL_TEAMS, "— every team —")] + [
            SelectChoice(str(t.id), t.name) for t in teams
        ]
        self.world.choices = [SelectChoice(w.name, w.title) for w in worlds().values()]
        return self

    def team_ids(self) -> list[int] | None:
        """Return the chosen team's id in a list, or None for every team."""
        return None if self.team.data == ALL_TEAMS else [int(self.team.data)]


class ImportForm(FlaskForm):
    """A season's schedule as YAML, uploaded or pasted."""

    schedule_file = FileField("YAML file")
    schedule_text = TextAreaField("or paste it here", validators=[Length(max=1_000_000)])

    def text(self) -> str:
        """Return the uploaded file's text, else the pasted text."""
        upload = self.schedule_file.data
        if upload is not None and getattr(upload, "filename", None):
            return str(upload.read().decode("utf-8", "replace"))
        return str(self.schedule_text.data or "")


class ReviewForm(FlaskForm):
    """An officer's decision on a run whose end could not be established."""

    decision = SelectField(
        "Decision",
        choices=[
            SelectChoice("accept", "Accept the end its logs show"),
            SelectChoice("fail", "Mark the run failed"),
        ],
        validators=[DataRequired()],
    )
    note = TextAreaField("What was checked", validators=[DataRequired(), Length(max=2000)])
