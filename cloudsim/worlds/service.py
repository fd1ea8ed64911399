"""The world definitions this CloudSim holds: read, check a task against them, update them.

The format and its check are drcsim's (`drcsim.worlds.check_document`); CloudSim stores the
documents (seeded from the worlds drcsim ships), hands one to the simulator with every run,
and propagates them to its team instances. Getters never commit; the caller does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drcsim.errors import WorldError
from drcsim.worlds import WorldSummary, check_document, document_digest, summarise
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.documents import as_json_data, check_depth, load_document
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import Role, Task, World, utcnow

__all__ = ["World", "WorldSummary", "check_world", "update_world", "worlds"]
MAX_DOCUMENT_BYTES = 256 * 1024


def stored_worlds() -> list[World]:
    """Return every world this CloudSim holds, by name."""
    return list(db.session.scalars(select(World).order_by(World.name)))


def worlds() -> dict[str, WorldSummary]:
    """Return every world's summary (title, run configurations, checkpoints), by name."""
    return {row.name: summarise(row.document) for row in stored_worlds()}


def get_world(actor: Actor, name: str) -> World:
    """Return a stored world (admins: its document shows every exact pose)."""
    require_role(actor, Role.ADMIN, "read world definitions")
    return _row(name)


def _row(name: str) -> World:
    row = db.session.scalar(select(World).where(World.name == name))
    if row is None:
        known = ", ".join(w.name for w in stored_worlds())
        raise NotFound(f"unknown world {name!r}; choose one of {known}")
    return row


def check_world(name: str, config: int) -> WorldSummary:
    """Return the stored world's summary, or raise InvalidInput naming the valid choices."""
    try:
        world = summarise(_row(name).document)
    except NotFound as exc:
        raise InvalidInput(str(exc)) from None
    if config not in world.configs:
        choices = ", ".join(map(str, world.configs))
        raise InvalidInput(f"{name} has no run configuration {config}; choose one of {choices}")
    return world


def world_for_run(name: str, config: int) -> World:
    """Return the stored world a run of (name, config) is built from, checked again."""
    check_world(name, config)
    return _row(name)


def parse_document(text: str | bytes) -> Any:
    """Return the data of an uploaded world file (JSON, or YAML, which JSON is a subset of)."""
    return load_document(text, "the world document", max_bytes=MAX_DOCUMENT_BYTES)


def checked(data: Any) -> dict[str, Any]:
    """Return a world document drcsim accepts (and that JSON can carry), or raise InvalidInput."""
    check_depth(data, "the world document")  # an API body is bounded too, but not this deep
    try:
        document = check_document(as_json_data(data, "the world document"))
    except WorldError as exc:
        raise InvalidInput(f"invalid world: {exc}") from None
    return document


@dataclass(frozen=True)
class WorldUpdate:
    """What an update did: the world as now stored, and whether it changed."""

    world: World
    changed: bool


def update_world(actor: Actor, data: Any, name: str | None = None) -> WorldUpdate:
    """Replace a world's document (admins) after drcsim's check; a new version if it differs."""
    require_role(actor, Role.ADMIN, "update world definitions")
    document = checked(data)
    if name is not None and document["name"] != name:
        raise InvalidInput(f"the document is world {document['name']!r}, not {name!r}")
    try:
        row = _row(document["name"])
    except NotFound as exc:
        raise InvalidInput(f"{exc} (a new world needs a simulator that ships it)") from None
    digest = document_digest(document)
    if digest == row.digest:
        return WorldUpdate(row, changed=False)
    _keep_configs_in_use(row.name, {int(key) for key in document["configs"]})
    row.document, row.digest, row.version, row.updated_at = (
        document,
        digest,
        row.version + 1,
        utcnow(),
    )
    db.session.flush()
    record(
        "world.update",
        actor,
        target_type="world",
        target_id=row.name,
        version=row.version,
        digest=digest,
    )
    return WorldUpdate(row, changed=True)


def _keep_configs_in_use(name: str, configs: set[int]) -> None:
    used = db.session.scalars(
        select(Task).where(Task.world == name, Task.run_config.not_in(configs))
    ).first()
    if used is not None:
        raise Conflict(
            f"task {used.name!r} uses {name} run configuration {used.run_config}, which the "
            "document drops: change or delete the task first"
        )


def put_world(name: str, version: int, document: dict[str, Any]) -> bool:
    """Make the stored world exactly this (a master's copy, checked); return whether it changed."""
    row = db.session.scalar(select(World).where(World.name == name))
    digest = document_digest(document)
    if row is None:
        db.session.add(World(name=name, version=version, digest=digest, document=document))
        return True
    if (row.digest, row.version) == (digest, version) and document_digest(row.document) == digest:
        return False
    row.document, row.digest, row.version, row.updated_at = document, digest, version, utcnow()
    return True
