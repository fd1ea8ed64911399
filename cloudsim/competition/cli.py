"""`cloudsim task`, `cloudsim schedule`, `cloudsim run`, `cloudsim leaderboard`."""

from __future__ import annotations

import json
import time
from typing import Any

import click
from drcsim.worlds import WORLD_NAMES

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import ID, app_context, emit, reports_errors
from cloudsim.cli.files import LoadedText, TextFile
from cloudsim.competition import live_view, schedule, season
from cloudsim.competition import runs as run_service
from cloudsim.extensions import db
from cloudsim.models import Run, Task
from cloudsim.people.service import find_team

LIVE_STATES = ("starting", "running", "stopping")


def task_data(task: Task) -> dict[str, object]:
    return {
        "id": task.id,
        "team": task.team.name,
        "name": task.name,
        "world": task.world,
        "run_config": task.run_config,
        "window_start": task.window_start.isoformat(),
        "window_stop": task.window_stop.isoformat(),
        "time_zone": task.time_zone,
        "timeout_s": task.timeout_s,
        "latency_ms": task.latency_ms,
        "uplink_bits": task.uplink_bits,
        "downlink_bits": task.downlink_bits,
        "order": task.order,
    }


def run_data(run: Run) -> dict[str, object]:
    return {
        "id": run.id,
        "task": run.task.name,
        "team": run.team.name,
        "state": run.state.value,
        "score": run.score,
        "falls": run.falls,
        "end_reason": run.end_reason,
        "error": run.error,
        "artifacts": {a.filename: a.sha256 for a in run.artifacts},
    }


@click.group()
def task() -> None:
    """Schedule, list and delete tasks."""


@task.command("add")
@click.option("--name", required=True)
@click.option("--world", required=True, type=click.Choice(WORLD_NAMES))
@click.option("--config", "run_config", default=1, show_default=True, type=int)
@click.option("--start", required=True, help="Window opens, e.g. '2026-06-17 09:00'.")
@click.option("--stop", required=True, help="Window closes.")
@click.option("--time-zone", default="UTC", show_default=True, help="Zone of --start/--stop.")
@click.option("--timeout", "timeout_s", default=schedule.DEFAULT_TIMEOUT_S, show_default=True)
@click.option("--latency-ms", default=schedule.DEFAULT_LATENCY_MS, show_default=True)
@click.option("--uplink-bits", default=schedule.DEFAULT_UPLINK_BITS, show_default=True)
@click.option("--downlink-bits", default=schedule.DEFAULT_DOWNLINK_BITS, show_default=True)
@click.option("--order", default=0, show_default=True)
@click.option("--team", "teams", multiple=True, help="Team name or id (repeat); none: every team.")
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def add(
    name: str,
    world: str,
    run_config: int,
    start: str,
    stop: str,
    time_zone: str,
    timeout_s: int,
    latency_ms: int,
    uplink_bits: int,
    downlink_bits: int,
    order: int,
    teams: tuple[str, ...],
    as_json: bool,
) -> None:
    """Schedule a task for some teams or every team."""
    with app_context():
        spec = schedule.TaskSpec(
            name=name,
            world=world,
            run_config=run_config,
            window_start=schedule.to_utc(start, time_zone),
            window_stop=schedule.to_utc(stop, time_zone),
            timeout_s=timeout_s,
            latency_ms=latency_ms,
            uplink_bits=uplink_bits,
            downlink_bits=downlink_bits,
            order=order,
            time_zone=time_zone,
        )
        team_ids = [find_team(t).id for t in teams] if teams else None
        created = schedule.schedule(SYSTEM, spec, team_ids)
        emit(
            [task_data(t) for t in created],
            as_json,
            "\n".join(f"task {t.id}: {t.name} for {t.team.name}" for t in created),
        )


@task.command("list")
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def list_tasks(as_json: bool) -> None:
    """List every task."""
    with app_context():
        tasks = db.session.scalars(schedule.visible_tasks(SYSTEM)).all()
        lines = [
            f"{t.id:5} {t.team.name:20} {t.name:30} {t.world}#{t.run_config} "
            f"{t.window_start:%Y-%m-%d %H:%M}-{t.window_stop:%Y-%m-%d %H:%M} UTC"
            for t in tasks
        ]
        emit([task_data(t) for t in tasks], as_json, "\n".join(lines) or "no tasks")


@task.command("delete")
@click.argument("task_id", type=ID)
@reports_errors
def delete(task_id: int) -> None:
    """Delete a task nobody has run."""
    with app_context():
        schedule.delete_task(SYSTEM, task_id)
        click.echo(f"deleted task {task_id}")


@click.group("schedule")
def schedule_group() -> None:
    """Import and export the season's schedule (YAML)."""


@schedule_group.command("import")
@click.argument("path", type=TextFile())
@reports_errors
def import_command(path: LoadedText) -> None:
    """Schedule every task of a season file (tasks already there are kept)."""
    with app_context():
        created = season.import_season(SYSTEM, path.text)
        click.echo(f"imported {path.name}: {len(created)} new task(s)")


@schedule_group.command("export")
@click.option("--time-zone", default=None, help="Write the windows in this zone.")
@reports_errors
def export_command(time_zone: str | None) -> None:
    """Print the season's schedule as YAML."""
    with app_context():
        click.echo(season.export_season(SYSTEM, time_zone), nl=False)


@click.group()
def run() -> None:
    """Start, stop and look at runs."""


@run.command("start")
@click.argument("task_id", type=ID)
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def start(task_id: int, as_json: bool) -> None:
    """Start a run of an open task on its team's constellation."""
    with app_context():
        started = run_service.start_run(SYSTEM, task_id)
        emit(run_data(started), as_json, f"run {started.id}: {started.state.value}")


@run.command("stop")
@click.argument("run_id", type=ID)
@reports_errors
def stop(run_id: int) -> None:
    """Stop a live run."""
    with app_context():
        stopped = run_service.stop_run(SYSTEM, run_id)
        click.echo(f"run {stopped.id}: {stopped.state.value}")


@run.command("show")
@click.argument("run_id", type=ID)
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def show(run_id: int, as_json: bool) -> None:
    """Show a run: state, score, logs."""
    with app_context():
        shown = run_service.get_run(SYSTEM, run_id)
        emit(
            run_data(shown),
            as_json,
            f"run {shown.id} ({shown.team.name}, {shown.task.name}): {shown.state.value}, "
            f"{shown.score} checkpoint(s), {shown.falls} fall(s), "
            f"ended by {shown.end_reason or '-'}",
        )


@run.command("watch")
@click.argument("run_id", type=ID)
@click.option("--lines", type=click.IntRange(min=1), help="Stop after this many lines.")
@click.option("--json", "as_json", is_flag=True, help="A JSON object a line (the API's body).")
@reports_errors
def watch(run_id: int, lines: int | None, as_json: bool) -> None:
    """Print a live run's figures once a second until it ends."""
    with app_context() as app:
        printed = 0
        while True:
            db.session.expire_all()  # the reader and the jobs change the row meanwhile
            now = live_view.live_status(app.config["CLOUDSIM"], run_service.get_run(SYSTEM, run_id))
            click.echo(json.dumps(now) if as_json else watch_line(now))
            printed += 1
            if now["state"] not in LIVE_STATES or (lines is not None and printed >= lines):
                break
            time.sleep(1.0)  # the pace of the output, not a wait for something


def watch_line(now: dict[str, Any]) -> str:
    """Return one line of `cloudsim run watch`."""
    rtf = "-" if now["rtf"] is None else f"{now['rtf']:.2f}"
    flags = " ".join(f["code"] for f in now["flags"])
    return (
        f"run {now['id']} {now['state']}: t={now['sim_seconds']:.1f}/{now['timeout_s']} s "
        f"rtf={rtf} score={now['score']} falls={now['falls']} "
        f"left up={now['bits_left']['uplink']:,} down={now['bits_left']['downlink']:,} bits"
        + (f" caps spent: {now['caps_spent']}" if now["caps_spent"] != "none" else "")
        + (f" {flags}" if flags else "")
        + (f" error {now['error_code'] or ''} {now['error']}" if now["error"] else "")
    )


@click.command()
@click.option("--json", "as_json", is_flag=True)
@reports_errors
def leaderboard(as_json: bool) -> None:
    """Print the ranking of the teams."""
    with app_context():
        standings = run_service.leaderboard(SYSTEM)
        lines = [
            f"{s.rank:3} {s.team:24} {s.checkpoints:3} checkpoints, "
            f"{100 * s.uplink_share_left:5.1f}% uplink left, {s.seconds_left:.0f} s left"
            + (f" ({s.invalidated} run(s) invalidated)" if s.invalidated else "")
            for s in standings
        ]
        emit([s.__dict__ for s in standings], as_json, "\n".join(lines) or "no teams")
