"""`cloudsim instance`: deploy, list, assign, check and terminate team instances."""

from __future__ import annotations

import dataclasses
import time

import click
from flask import current_app

from cloudsim.auth.master import restore_configured_access
from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, commit, emit, reports_errors
from cloudsim.cli.files import LoadedText, TextFile
from cloudsim.extensions import db
from cloudsim.launched_constellations.cli import follow_job
from cloudsim.models import InstanceState, TeamInstance
from cloudsim.people.service import find_team
from cloudsim.providers.service import PROVIDERS, servers_settings
from cloudsim.team_instances import launch as launches
from cloudsim.team_instances import service
from cloudsim.team_instances.poll import check_instances
from cloudsim.team_instances.restore import restore_access as restore_access_over_ssh


def instance_data(instance: TeamInstance) -> dict[str, object]:
    return {
        "id": instance.id,
        "name": instance.name,
        "team": instance.team.name if instance.team else None,
        "state": instance.state.value,
        "url": instance.url,
        "version": instance.version,
        "health": instance.health,
        "error": instance.error,
        "checked_at": instance.checked_at,
        "heard_at": instance.heard_at,
        "last_sync_at": instance.last_sync_at,
        "sync_error": instance.sync_error,
        "sync_report": instance.sync_report,
        "launch": instance.launch,
    }


def _line(instance: TeamInstance) -> str:
    team = instance.team.name if instance.team else "spare"
    why = f" ({instance.error})" if instance.error else ""
    return f"{instance.name}  {team}  {instance.state.value}{why}  {instance.url or ''}"


@click.group()
def instance() -> None:
    """Deploy and watch team instances (a CloudSim per team, run from this master)."""


@instance.command("deploy")
@click.option("--name", required=True, help="Instance name (lowercase, digits, '-').")
@click.option("--provider", default="local", show_default=True, type=click.Choice(PROVIDERS))
@click.option("--team", "team_name", help="Team name or id (none: spares).")
@click.option("--count", default=1, show_default=True, type=click.IntRange(1, 50))
@click.option("--wait", is_flag=True, help="Follow the deployment to its end and check it.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def deploy(
    name: str, provider: str, team_name: str | None, count: int, wait: bool, as_json: bool
) -> None:
    """Deploy a team's CloudSim, or COUNT spares named NAME-1..N."""
    with app_context():
        team_id = find_team(team_name).id if team_name else None
        deployed = service.deploy(
            SYSTEM, name=name, provider=provider, team_id=team_id, count=count
        )
        if wait:
            for _, job in deployed:
                follow_job(job.id, as_json)
            db.session.expire_all()
            check_instances(current_app.config["CLOUDSIM"], [i.id for i, _ in deployed])
        instances = [i for i, _ in deployed]
        emit(
            [instance_data(i) for i in instances],
            as_json,
            "\n".join(_line(i) for i in instances),
        )


@instance.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_instances(as_json: bool) -> None:
    """List team instances with their state and health."""
    with app_context():
        instances = db.session.scalars(service.visible_instances(SYSTEM)).all()
        emit(
            [instance_data(i) for i in instances],
            as_json,
            "\n".join(_line(i) for i in instances) or "no team instances",
        )


@instance.command("check")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def check(as_json: bool) -> None:
    """Check every live instance's health now (what the beat does periodically)."""
    with app_context():
        instances = check_instances(current_app.config["CLOUDSIM"])
        emit(
            [instance_data(i) for i in instances],
            as_json,
            "\n".join(_line(i) for i in instances) or "no live team instances",
        )


@instance.command("restore-access")
@click.argument("name", required=False)
@click.option(
    "--here",
    is_flag=True,
    help="On a team instance: restore its master's account and token from its own settings.",
)
@reports_errors
def restore_access(name: str | None, here: bool) -> None:
    """Give the master back its admin account and token on instance NAME (through its SSH
    route), then check that the instance answers the master again."""
    if here == bool(name):
        raise click.UsageError("name an instance (on the master) or give --here (on it)")
    with app_context():
        if here:
            for line in restore_configured_access() or ["the master's access was whole"]:
                click.echo(line)
            return
        found = service.get_instance(SYSTEM, name or "")
        for line in restore_access_over_ssh(found, current_app.config["CLOUDSIM"]):
            click.echo(f"{found.name}: {line}")
        commit()
        check_instances(current_app.config["CLOUDSIM"], [found.id])
        if found.state != InstanceState.READY:
            raise click.ClickException(f"{found.name} still does not answer: {found.error}")
        click.echo(f"{found.name}: answers the master again")


@instance.command("assign")
@click.argument("name")
@click.option("--team", "team_name", required=True, help="Team name or id.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def assign(name: str, team_name: str, as_json: bool) -> None:
    """Give a spare instance to a team."""
    with app_context():
        found = service.assign(SYSTEM, name, find_team(team_name).id)
        emit(instance_data(found), as_json, _line(found))


@instance.command("terminate")
@click.argument("name")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def terminate(name: str, as_json: bool) -> None:
    """Terminate an instance's machines (its record stays, as history)."""
    with app_context():
        job = service.terminate(SYSTEM, name)
        found = service.get_instance(SYSTEM, name)
        emit(instance_data(found) | {"job": job.id}, as_json, f"{_line(found)} (job {job.id})")


@instance.command("provider")
@click.argument("name")
# the only provider an inventory file sets up; ec2's fields go on the page or the API
@click.argument("provider", type=click.Choice(["servers"]))
@click.option(
    "--inventory",
    "inventory_file",
    required=True,
    type=TextFile(),
    help="The YAML inventory of the machines this instance launches on.",
)
@reports_errors
def provider(name: str, provider: str, inventory_file: LoadedText) -> None:
    """Keep (encrypted) the provider settings handed to instance NAME when it launches."""
    settings = servers_settings(inventory_file.text, inventory_file.name)
    with app_context():
        found = launches.set_provider_settings(SYSTEM, name, provider, settings)
        click.echo(f"{found.name}: {provider} settings kept (encrypted), handed over at launch")


def _summary_line(outcome: launches.Outcome) -> str:
    why = f" ({outcome.why})" if outcome.why else ""
    return f"{outcome.instance}  {outcome.team or 'spare'}  {outcome.state}{why}"


@instance.command("launch")
@click.argument("names", nargs=-1)
@click.option("--all", "every", is_flag=True, help="Every team's instance.")
@click.option("--kind", default="vrc", show_default=True, help="Constellation kind.")
@click.option("--provider", default="servers", show_default=True, type=click.Choice(PROVIDERS))
@click.option("--wait", is_flag=True, help="Follow the launches until each is ready or failed.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def launch(
    names: tuple[str, ...], every: bool, kind: str, provider: str, wait: bool, as_json: bool
) -> None:
    """Launch each team's constellation through its instance; say who is ready, launching
    or failed (and why)."""
    if every == bool(names):
        raise click.UsageError("name instances or give --all")
    with app_context():
        refs: list[int | str] | None = None if every else list(names)
        summary = launches.launch(SYSTEM, kind, provider, refs)
        going = [o for o in summary if o.state == "launching"]
        if wait and going:
            for outcome in going:
                if outcome.job_id:
                    follow_job(outcome.job_id, True)
            seen = {o.instance_id: o for o in _wait([o.instance_id for o in going])}
            summary = [seen.get(o.instance_id, o) for o in summary]
        emit(
            [dataclasses.asdict(o) for o in summary],
            as_json,
            "\n".join(_summary_line(o) for o in summary) or "no team instances",
        )


def _wait(ids: list[int], interval: float = 5, timeout: float = 3600) -> list[launches.Outcome]:
    """Poll the instances until no launch is still going; return the summary."""
    deadline = time.monotonic() + timeout
    while True:
        db.session.expire_all()
        instances = check_instances(current_app.config["CLOUDSIM"], ids)
        commit()
        summary = [launches.outcome(i) for i in instances]
        if time.monotonic() > deadline or all(o.state != "launching" for o in summary):
            return summary
        time.sleep(interval)
