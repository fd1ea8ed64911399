"""`cloudsim world`: list, show and update the world definitions runs are built from."""

from __future__ import annotations

import json

import click

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.cli.files import LoadedText, TextFile
from cloudsim.models import World
from cloudsim.worlds import service


def world_data(world: World) -> dict[str, object]:
    return {
        "name": world.name,
        "title": world.document.get("title"),
        "version": world.version,
        "digest": world.digest,
        "configs": sorted(int(key) for key in world.document.get("configs", {})),
        "updated_at": world.updated_at,
    }


def _line(world: World) -> str:
    return f"{world.name}  version {world.version}  {world.digest[:12]}  {world.document['title']}"


@click.group()
def world() -> None:
    """World definitions: run configurations and scoring rules, as data."""


@world.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_worlds(as_json: bool) -> None:
    """List the worlds with their versions and digests."""
    with app_context():
        found = service.stored_worlds()
        emit([world_data(w) for w in found], as_json, "\n".join(_line(w) for w in found))


@world.command("show")
@click.argument("name")
@reports_errors
def show(name: str) -> None:
    """Print a world's document (JSON), e.g. to edit and update it."""
    with app_context():
        click.echo(json.dumps(service.get_world(SYSTEM, name).document, indent=2))


@world.command("update")
@click.argument("path", type=TextFile(service.MAX_DOCUMENT_BYTES))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def update(path: LoadedText, as_json: bool) -> None:
    """Replace a world's document with the one in PATH (JSON or YAML); checked first."""
    with app_context():
        done = service.update_world(SYSTEM, service.parse_document(path.text))
        what = "updated" if done.changed else "unchanged"
        emit(
            world_data(done.world) | {"changed": done.changed},
            as_json,
            f"{_line(done.world)} ({what})",
        )
