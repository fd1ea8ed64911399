"""`cloudsim constellation`: launch, list, show, terminate, and run commands on machines."""

from __future__ import annotations

import sys
import time

import click
from flask import current_app

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, commit, emit, reports_errors
from cloudsim.extensions import db
from cloudsim.jobs.service import run_here, workers_alive
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.capacity import describe, room
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.launched_constellations.reconcile import (
    destroy_orphans,
    find_orphans,
    incomplete_terminations,
)
from cloudsim.models import Constellation, Job
from cloudsim.people.service import find_team
from cloudsim.providers.service import PROVIDERS
from constellations.definition import available_kinds
from provisioners.remote.ssh import SSHExecutor

WORKER_HINT_SECONDS = 10


def constellation_data(constellation: Constellation) -> dict[str, object]:
    return {
        "id": constellation.id,
        "name": constellation.name,
        "kind": constellation.kind,
        "provider": constellation.provider,
        "state": constellation.state.value,
        "team": constellation.team.name if constellation.team else None,
        "error": constellation.error,
        "machines": [
            {
                "name": m.name,
                "role": m.role,
                "state": m.state.value,
                "private_ip": m.private_ip,
                "public_ip": m.public_ip,
                "verification": m.verification,
            }
            for m in constellation.machines
        ],
    }


def follow_job(job_id: str, quiet: bool) -> Job:
    """Follow a job to its end, with a progress bar on a terminal; run it here if no worker
    is alive (after Ctrl-C on `cloudsim up`, nothing else would)."""
    commit()  # the command's work so far: the job row exists and its message is sent
    if not workers_alive():
        click.echo("no worker is running: running the job in this process", err=True)
        run_here(job_id)
    started = time.monotonic()
    hinted = False
    show = not quiet and sys.stderr.isatty()
    with (
        click.progressbar(length=100, label="starting", file=sys.stderr, show_eta=False)
        if show
        else _NoBar() as bar
    ):
        done = 0
        while True:
            db.session.expire_all()
            job = db.session.get(Job, job_id)
            assert job is not None
            bar.label = f"{job.stage or job.state.value:10}"
            bar.update(job.progress - done)
            done = job.progress
            if job.state.final:
                return job
            if (
                job.state.value == "queued"
                and not hinted
                and (time.monotonic() - started > WORKER_HINT_SECONDS)
            ):
                click.echo("still queued: is a worker running (cloudsim up)?", err=True)
                hinted = True
            time.sleep(0.5)


def _follow(found: Constellation, job: Job, what: str, wait: bool, as_json: bool) -> None:
    """Print the constellation and its job, after following the job to its end with --wait."""
    if wait:
        job = follow_job(job.id, as_json)
        db.session.refresh(found)
    emit(
        constellation_data(found) | {"job": job.id},
        as_json,
        f"{found.name}: {found.state.value} (job {job.id})",
    )
    if wait and job.state.value == "failed":
        raise click.ClickException(f"{what} failed: {found.error or job.error}")


class _NoBar:
    label = ""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *args: object) -> None:
        return None

    def update(self, steps: int) -> None:
        return None


@click.group()
def constellation() -> None:
    """Launch, list, show and terminate constellations."""


@constellation.command("launch")
@click.option("--name", required=True, help="Constellation name (lowercase, digits, '-').")
@click.option("--kind", required=True, type=click.Choice(available_kinds()))
@click.option("--provider", default="local", show_default=True, type=click.Choice(PROVIDERS))
@click.option("--team", "team_name", help="Team name or id.")
@click.option("--wait", is_flag=True, help="Follow the launch to its end.")
@click.option("--json", "as_json", is_flag=True, help="Print the constellation as JSON.")
@reports_errors
def launch(
    name: str, kind: str, provider: str, team_name: str | None, wait: bool, as_json: bool
) -> None:
    """Launch a constellation."""
    with app_context():
        team_id = find_team(team_name).id if team_name else None
        created, job = service.launch(
            SYSTEM, name=name, kind=kind, provider=provider, team_id=team_id
        )
        _follow(created, job, "launch", wait, as_json)
        if not as_json:
            click.echo(describe(room(provider, current_app.config["CLOUDSIM"])))


@constellation.command("capacity")
@click.option("--provider", default="local", show_default=True, type=click.Choice(PROVIDERS))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def capacity(provider: str, as_json: bool) -> None:
    """Say how many more machines (and constellations of each kind) a provider can take."""
    with app_context():
        found = room(provider, current_app.config["CLOUDSIM"])
        data: dict[str, object] = {"provider": provider, "known": found is not None}
        if found is not None:
            data |= {
                "hosts": found.capacity.hosts,
                "networks": found.capacity.networks,
                "public_addresses": found.capacity.public,
                "limited_by": found.capacity.limited_by,
                "bounds": found.capacity.bounds,
                "memory_mib": found.capacity.memory_mib,
                "memory_limited_by": found.capacity.memory_limited_by,
                "host_memory_mib": found.capacity.host_memory_mib,
                "kinds": found.kinds,
            }
        emit(data, as_json, describe(found))


@constellation.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_constellations(as_json: bool) -> None:
    """List constellations."""
    with app_context():
        rows = db.session.scalars(service.visible_constellations(SYSTEM)).all()
        lines = "\n".join(
            f"{c.name}\t{c.kind}\t{c.provider}\t{c.state.value}\t{c.team.name if c.team else '-'}"
            for c in rows
        )
        emit([constellation_data(c) for c in rows], as_json, lines or "no constellations")


@constellation.command("show")
@click.argument("name")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def show(name: str, as_json: bool) -> None:
    """Show a constellation's machines, roles, addresses and states."""
    with app_context():
        found = service.get_constellation(SYSTEM, name)
        lines = [f"{found.name} ({found.kind} on {found.provider}): {found.state.value}"]
        if found.error:
            lines.append(f"error: {found.error}")
        for m in found.machines:
            lines.append(
                f"  {m.name:8} {m.role:8} {m.private_ip or '-':15} "
                f"{m.public_ip or '-':15} {m.state.value}"
            )
        emit(constellation_data(found), as_json, "\n".join(lines))


@constellation.command("terminate")
@click.argument("name")
@click.option("--wait", is_flag=True, help="Follow the termination to its end.")
@click.option("--json", "as_json", is_flag=True, help="Print the constellation as JSON.")
@reports_errors
def terminate(name: str, wait: bool, as_json: bool) -> None:
    """Terminate a constellation, releasing every resource it has."""
    with app_context():
        found = service.get_constellation(SYSTEM, name)
        _follow(found, service.terminate(SYSTEM, found.id), "terminate", wait, as_json)


@constellation.command("orphans")
@click.option(
    "--destroy", is_flag=True, help="Destroy them (they belong to no live constellation)."
)
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def orphans(destroy: bool, as_json: bool) -> None:
    """List provider nodes that no live constellation owns, and terminates left incomplete;
    --destroy removes the nodes (an incomplete terminate is retried with `terminate`)."""
    with app_context() as app:
        config = app.config["CLOUDSIM"]
        found = destroy_orphans(SYSTEM, config) if destroy else find_orphans(config)
        incomplete = incomplete_terminations()
        verb = "destroyed" if destroy else "orphan"
        lines = [f"{verb}: {o.provider} {o.name} ({o.node_id}) of {o.constellation}" for o in found]
        lines += [
            f"terminate incomplete: {c.provider} {c.name}: {c.error} "
            f"(retry: cloudsim constellation terminate {c.name})"
            for c in incomplete
        ]
        data: list[dict[str, object]] = [o.__dict__ for o in found]
        data += [
            {
                "provider": c.provider,
                "node_id": None,
                "name": c.name,
                "constellation": c.name,
                "terminate_incomplete": c.error,
            }
            for c in incomplete
        ]
        emit(data, as_json, "\n".join(lines) or "no orphan nodes")


@constellation.command("ssh", context_settings={"ignore_unknown_options": True})
@click.argument("name")
@click.argument("machine")
@click.argument("command", nargs=-1, required=True, type=click.UNPROCESSED)
@reports_errors
def ssh(name: str, machine: str, command: tuple[str, ...]) -> None:
    """Run COMMAND on MACHINE of constellation NAME (after `--`)."""
    with app_context() as app:
        found = service.get_constellation(SYSTEM, name)
        keys = constellation_keypair(found)
        reach = targets(found, keys, app.config["CLOUDSIM"])
        if machine not in reach:
            raise click.ClickException(
                f"{name} has no machine {machine!r} (machines: {', '.join(reach)})"
            )
        with SSHExecutor(machine_host_keys(found), secrets=[keys.private]) as executor:
            result = executor.run(reach[machine], " ".join(command), check=False)
        click.echo(result.stdout, nl=False)
        click.echo(result.stderr, nl=False, err=True)
        sys.exit(result.exit_code)
