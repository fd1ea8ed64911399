"""`cloudsim phase`: list the season's phases, schedule one's tasks, reveal its scores."""

from __future__ import annotations

import click

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.models import Phase
from cloudsim.seasons import service


def phase_data(phase: Phase) -> dict[str, object]:
    return {
        "id": phase.id,
        "name": phase.name,
        "window_start": phase.window_start.isoformat(),
        "window_stop": phase.window_stop.isoformat(),
        "worlds": [f"{world}#{config}" for world, config in phase.worlds],
        "entry": "all"
        if phase.entry_phase is None
        else f"{phase.entry_phase.name} >= {phase.entry_min_score}",
        "limits": {
            key.removeprefix("max_runs_"): getattr(phase, key)
            for key in service.LIMITS
            if getattr(phase, key) is not None
        },
        "scores": "live"
        if not phase.scores_hidden
        else ("revealed" if phase.revealed_at else "hidden"),
        "ranking": phase.counts_in_ranking,
    }


@click.group()
def phase() -> None:
    """List, schedule and reveal the season's phases.

    Phases are written in the season YAML (cloudsim schedule import).
    """


@phase.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_command(as_json: bool) -> None:
    """Print the season's phases and their rules."""
    with app_context():
        rows = [phase_data(p) for p in service.list_phases()]
        lines = [
            f"{r['id']:>3}  {r['name']:<16} {r['window_start']} .. {r['window_stop']}"
            f"  entry {r['entry']}  limits {r['limits'] or '-'}  scores {r['scores']}"
            f"  {'ranked' if r['ranking'] else 'not ranked'}"
            for r in rows
        ]
        emit(rows, as_json, "\n".join(lines) or "no phases")


@phase.command("schedule")
@click.argument("name")
@reports_errors
def schedule_command(name: str) -> None:
    """Make the phase's tasks for every team that may enter it now."""
    with app_context():
        created = service.schedule_phase(SYSTEM, service.find_phase(SYSTEM, name))
        click.echo(f"{name}: {len(created)} new task(s)")


@phase.command("reveal")
@click.argument("name")
@reports_errors
def reveal_command(name: str) -> None:
    """Show the phase's hidden scores to the teams from now on."""
    with app_context():
        revealed = service.reveal(SYSTEM, service.find_phase(SYSTEM, name))
        click.echo(
            f"{name}: scores shown to the teams since {revealed.revealed_at:%Y-%m-%d %H:%M} UTC"
        )
