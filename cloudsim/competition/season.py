"""A season's schedule as YAML: teams x a sequence of tasks, imported and exported again.

time_zone: America/Los_Angeles      # how the windows below are written
teams: [Team A, Team B]             # who runs the tasks; left out: every team
tasks:
  - name: Driving, run 1
    world: vrc_task_1
    config: 1
    start: 2026-06-17 09:00
    stop: 2026-06-17 12:00
    timeout_s: 1800
    latency_ms: 250
    uplink_bits: 115200
    downlink_bits: 59000000
    order: 1
    teams: [Team A]                 # optional: this task for these teams only
"""

from __future__ import annotations

from collections import defaultdict
from datetime import datetime
from functools import lru_cache
from typing import Any

import yaml
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.competition.schedule import (
    DEFAULT_DOWNLINK_BITS,
    DEFAULT_LATENCY_MS,
    DEFAULT_TIMEOUT_S,
    DEFAULT_UPLINK_BITS,
    TaskSpec,
    add_task,
    check_spec,
    in_zone,
    to_utc,
    visible_tasks,
    zone,
)
from cloudsim.documents import BoundedLoader, load_document
from cloudsim.errors import InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import Role, Task, Team, utcnow
from cloudsim.seasons.document import parse_phases, phase_entries
from cloudsim.seasons.service import PhaseSpec, list_phases, save_phase, schedule_phase

MAX_TASKS = 1000
# libyaml's emitter when PyYAML was built with it (its wheels are), else the pure-Python one
SafeDumper: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
TASK_KEYS = {
    "name",
    "world",
    "config",
    "start",
    "stop",
    "timeout_s",
    "latency_ms",
    "uplink_bits",
    "downlink_bits",
    "order",
    "teams",
    "time_zone",
}


class SeasonLoader(BoundedLoader):
    """YAML's safe loader that keeps times as the text they are (the task's zone gives their
    meaning); YAML's own timestamps lose the zone, turn a date-only value into a date, and
    raise on 2026-02-30."""


SeasonLoader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:timestamp"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}


def parse_season(text: str) -> tuple[list[tuple[TaskSpec, list[str] | None]], str]:
    """Read a season document into (spec, team names or None for all) pairs and its zone."""
    entries, _, zone_name = read_season(text)
    return entries, zone_name


def read_season(
    text: str,
) -> tuple[list[tuple[TaskSpec, list[str] | None]], list[PhaseSpec], str]:
    """Read a season document into its task entries, its phases and its zone."""
    document = load_document(
        text, "the schedule", loader=SeasonLoader, not_parsed="{what} is not valid YAML"
    )
    if not isinstance(document, dict) or not (
        isinstance(document.get("tasks"), list) or "phases" in document
    ):
        raise InvalidInput(
            "the schedule must be a mapping with a 'tasks' list, a 'phases' list or both"
        )
    unknown = set(document) - {"time_zone", "teams", "tasks", "phases"}
    if unknown:
        raise InvalidInput(f"unknown schedule keys: {', '.join(sorted(map(str, unknown)))}")
    zone_name = str(document.get("time_zone") or "UTC")
    zone(zone_name)
    phases = parse_phases(document["phases"], zone_name) if "phases" in document else []
    document.setdefault("tasks", [])
    if not isinstance(document["tasks"], list):
        raise InvalidInput("tasks must be a list")
    default_teams = _team_names(document.get("teams"), "teams")
    if len(document["tasks"]) > MAX_TASKS:
        raise InvalidInput(f"a schedule holds at most {MAX_TASKS} tasks")
    entries = []
    for number, item in enumerate(document["tasks"], start=1):
        try:
            entries.append(_entry(item, zone_name, default_teams))
        except InvalidInput as exc:
            raise InvalidInput(f"task {number}: {exc}") from None
    return entries, phases, zone_name


def _entry(
    item: Any, zone_name: str, default_teams: list[str] | None
) -> tuple[TaskSpec, list[str] | None]:
    if not isinstance(item, dict):
        raise InvalidInput("each task must be a mapping")
    unknown = set(item) - TASK_KEYS
    if unknown:
        raise InvalidInput(f"unknown keys {', '.join(sorted(map(str, unknown)))}")
    missing = [k for k in ("name", "world", "start", "stop") if k not in item]
    if missing:
        raise InvalidInput(f"missing {', '.join(missing)}")
    task_zone = str(item.get("time_zone") or zone_name)
    try:
        spec = TaskSpec(
            name=str(item["name"]),
            world=str(item["world"]),
            run_config=_whole(item.get("config", 1), "config"),
            window_start=to_utc(str(item["start"]), task_zone),
            window_stop=to_utc(str(item["stop"]), task_zone),
            timeout_s=_whole(item.get("timeout_s", DEFAULT_TIMEOUT_S), "timeout_s"),
            latency_ms=_whole(item.get("latency_ms", DEFAULT_LATENCY_MS), "latency_ms"),
            uplink_bits=_whole(item.get("uplink_bits", DEFAULT_UPLINK_BITS), "uplink_bits"),
            downlink_bits=_whole(item.get("downlink_bits", DEFAULT_DOWNLINK_BITS), "downlink_bits"),
            order=_whole(item.get("order", 0), "order"),
            time_zone=task_zone,
        )
    except InvalidInput as exc:
        raise InvalidInput(f"{item.get('name', '?')}: {exc}") from None
    teams = _team_names(item["teams"], "teams") if "teams" in item else default_teams
    return check_spec(spec), teams


def _whole(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise InvalidInput(f"{name} must be a whole number")
    try:
        return int(value)
    except ValueError:
        raise InvalidInput(f"{name} must be a whole number, got {value!r}") from None


def _team_names(value: Any, name: str) -> list[str] | None:
    if value is None or value == "all":
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value) or not value:
        raise InvalidInput(f"{name} must be 'all' or a list of team names")
    return value


def import_season(actor: Actor, text: str) -> list[Task]:
    """Save the document's phases and schedule every task of it (those of each phase for the
    teams that may enter it now); tasks already scheduled are left alone."""
    require_role(actor, Role.OFFICER, "import schedules")
    entries, phase_specs, _ = read_season(text)
    all_teams = list(db.session.scalars(select(Team).order_by(Team.name)))
    by_name = {t.name.lower(): t for t in all_teams}
    existing = {
        (t.team_id, t.name, t.window_start, t.world, t.run_config)
        for t in db.session.scalars(select(Task))
    }
    planned = []
    for spec, names in entries:
        if names is None:
            teams = all_teams
        else:
            teams = []
            for team_name in names:
                team = by_name.get(team_name.strip().lower())
                if team is None:
                    raise NotFound(f"{spec.name}: no team named {team_name!r}")
                teams.append(team)
        planned += [(spec, team) for team in teams]
    created = []
    for spec, team in planned:
        key = (team.id, spec.name, spec.window_start, spec.world, spec.run_config)
        if key not in existing:
            existing.add(key)
            created.append(add_task(actor, spec, team))
    for phase_spec in phase_specs:
        phase = save_phase(actor, phase_spec)
        if phase.entry_phase is None or phase.entry_phase.window_stop <= utcnow():
            created += schedule_phase(actor, phase)
        # else: its entrants are known once the earlier phase closes (`cloudsim phase schedule`)
    record(
        "schedule.import",
        actor,
        tasks=len(entries),
        phases=len(phase_specs),
        created=len(created),
    )
    return created


def export_season(actor: Actor, zone_name: str | None = None) -> str:
    """Write every scheduled task as a season document (the same task for several teams once)."""
    require_role(actor, Role.OFFICER, "export schedules")
    columns = [getattr(Task, name) for name in SPEC_FIELDS]
    tasks = (
        visible_tasks(actor)
        .with_only_columns(*columns, Team.name)
        .join(Task.team)
        .where(Task.phase_id.is_(None))  # a phase's tasks follow from the phase
    )
    rows = tuple(tuple(row) for row in db.session.execute(tasks))
    all_names = tuple(sorted(db.session.scalars(select(Team.name))))
    text = _season_document(rows, all_names, zone_name)
    phases = list_phases()
    if not phases:
        return text
    entries = phase_entries(phases, _document_zone(rows, zone_name))
    return text + yaml.dump(
        {"phases": entries}, Dumper=SafeDumper, sort_keys=False, allow_unicode=True
    )


# Drawing a season's YAML costs ~50 ms (480 tasks), reading its rows ~3 ms: the document is
# a function of exactly the rows the caller may see, so it is kept per process for those rows
# and drawn again as soon as any of them (or a team's name) differs; never stale, never shared
# beyond what the rows already show.
@lru_cache(maxsize=8)
def _season_document(
    rows: tuple[tuple[Any, ...], ...], all_names: tuple[str, ...], zone_name: str | None
) -> str:
    """Draw the season document of these (spec fields..., team name) rows."""
    document_zone = _document_zone(rows, zone_name)
    groups: dict[tuple[Any, ...], list[str]] = defaultdict(list)
    for row in rows:
        groups[row[:-1]].append(row[-1])  # the spec's fields, then the team's name
    entries = []
    for spec, names in groups.items():
        entry = _entry_of(dict(zip(SPEC_FIELDS, spec, strict=True)), document_zone)
        if sorted(names) != list(all_names):
            entry["teams"] = sorted(names)
        entries.append(entry)
    document = {"time_zone": document_zone, "tasks": entries}
    return yaml.dump(document, Dumper=SafeDumper, sort_keys=False, allow_unicode=True)


def _document_zone(rows: tuple[tuple[Any, ...], ...], zone_name: str | None) -> str:
    """Return the zone the document is written in: the one asked for, or the tasks' own."""
    zones = {row[SPEC_FIELDS.index("time_zone")] for row in rows}
    document_zone = zone_name or (zones.pop() if len(zones) == 1 else "UTC")
    zone(document_zone)
    return document_zone


SPEC_FIELDS = (
    "name",
    "world",
    "run_config",
    "window_start",
    "window_stop",
    "timeout_s",
    "latency_ms",
    "uplink_bits",
    "downlink_bits",
    "order",
    "time_zone",
)


def _entry_of(spec: dict[str, Any], document_zone: str) -> dict[str, Any]:
    task_zone = spec["time_zone"]
    entry: dict[str, Any] = {
        "name": spec["name"],
        "world": spec["world"],
        "config": spec["run_config"],
        "start": _wall_clock(spec["window_start"], task_zone),
        "stop": _wall_clock(spec["window_stop"], task_zone),
        "timeout_s": spec["timeout_s"],
        "latency_ms": spec["latency_ms"],
        "uplink_bits": spec["uplink_bits"],
        "downlink_bits": spec["downlink_bits"],
        "order": spec["order"],
    }
    if task_zone != document_zone:
        entry["time_zone"] = task_zone
    return entry


def _wall_clock(value: datetime, zone_name: str) -> str:
    local = in_zone(value, zone_name)
    return local.strftime("%Y-%m-%d %H:%M" + (":%S" if local.second else ""))
