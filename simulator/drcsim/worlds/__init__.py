"""World definitions: each task world is a JSON document with its run configurations and its
scoring rules as data. drcsim ships one per task; an orchestrator may hand over its own copy
(`drcsim serve --world-file`), checked by `check_document` before anything is built."""

from __future__ import annotations

import copy
import hashlib
import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from drcsim.errors import WorldError
from drcsim.worlds.schema import (
    check_config_overrides,
    check_object,
    check_terrain,
    check_top,
)

WORLD_NAMES = ("vrc_task_1", "vrc_task_2", "vrc_task_3")
CONFIG_NAMES = ("1", "2", "3", "4", "5")


@dataclass(frozen=True)
class WorldSpec:
    """One world in one run configuration, with the configuration's overrides applied."""

    name: str
    config: str
    title: str
    seed: int
    time_limit_s: float
    ground_friction: float
    robot_start: tuple[float, float, float]
    objects: dict[str, dict[str, Any]]
    terrain: dict[str, dict[str, Any]]
    checkpoints: list[dict[str, Any]]
    assists: dict[str, float]
    digest: str = ""  # of the whole document this was resolved from


def shipped_document(name: str) -> dict[str, Any]:
    """Return the world document drcsim ships for `name`."""
    if name not in WORLD_NAMES:
        raise WorldError(f"unknown world {name!r} (known: {', '.join(WORLD_NAMES)})")
    text = resources.files(__package__).joinpath(f"{name}.json").read_text()
    data: dict[str, Any] = json.loads(text)
    return data


def document_digest(document: dict[str, Any]) -> str:
    """Return the SHA-256 of a document's canonical JSON (key order and spacing do not count)."""
    canonical = json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(canonical.encode()).hexdigest()


def check_document(data: Any) -> dict[str, Any]:
    """Return `data` if it is a world document every configuration of which loads; else
    raise WorldError saying where and what is wrong."""
    doc = check_top(data)
    configs = doc["configs"]
    if not isinstance(configs, dict) or not configs:
        raise WorldError(f"{doc['name']}.configs: must be an object with run configurations")
    for key, overrides in configs.items():
        check_config_overrides(doc["name"], key, overrides)
        spec = _resolve(doc, key, None)
        where = f"{doc['name']}.configs.{key}"
        for item_id, item in spec.objects.items():
            check_object(item, f"{where}.objects.{item_id}")
        for patch_id, patch in spec.terrain.items():
            check_terrain(patch, f"{where}.terrain.{patch_id}")
    return doc


def read_world_file(path: Path) -> dict[str, Any]:
    """Return the checked world document in a JSON file."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise WorldError(f"cannot read world file {path}: {exc}") from None
    return check_document(data)


@dataclass(frozen=True)
class WorldSummary:
    """What an orchestrator schedules: a world's title, run configurations and checkpoints."""

    name: str
    title: str
    configs: tuple[int, ...]
    checkpoints: tuple[str, ...]


def world_summaries() -> dict[str, WorldSummary]:
    """Return every world by name, summarised (no physics is loaded)."""
    found: dict[str, WorldSummary] = {}
    for name in WORLD_NAMES:
        found[name] = summarise(shipped_document(name))
    return found


def summarise(document: dict[str, Any]) -> WorldSummary:
    """Return a (checked) world document's summary."""
    return WorldSummary(
        name=document["name"],
        title=document.get("title", document["name"]),
        configs=tuple(sorted(int(c) for c in document["configs"])),
        checkpoints=tuple(c["name"] for c in document["checkpoints"]),
    )


def _by_id(items: list[dict[str, Any]], overrides: dict[str, dict[str, Any]], kind: str) -> dict:
    resolved = {item["id"]: copy.deepcopy(item) for item in items}
    for item_id, override in overrides.items():
        if item_id not in resolved:
            raise WorldError(f"configuration overrides unknown {kind} {item_id!r}")
        resolved[item_id].update(override)
    return resolved


def load_world(
    name: str,
    config: str | int,
    time_limit_s: float | None = None,
    document: dict[str, Any] | None = None,
) -> WorldSpec:
    """Return world `name` in run configuration `config`, from `document` (checked) if
    given, else from the shipped copy."""
    if document is None:
        return _resolve(shipped_document(name), str(config), time_limit_s)
    raw = check_document(document)
    if raw["name"] != name:
        raise WorldError(f"the world document is {raw['name']!r}, not {name!r}")
    return _resolve(raw, str(config), time_limit_s)


def _resolve(raw: dict[str, Any], config_key: str, time_limit_s: float | None) -> WorldSpec:
    name = raw["name"]
    if config_key not in raw["configs"]:
        raise WorldError(f"world {name} has no configuration {config_key!r}")
    overrides = raw["configs"][config_key]
    robot = {**raw["robot"], **overrides.get("robot", {})}
    ground = {**raw["ground"], **overrides.get("ground", {})}
    start = tuple(float(v) for v in robot["start"])
    if len(start) != 3:
        raise WorldError(f"{name}/{config_key}: robot start must be [x, y, yaw]")
    return WorldSpec(
        name=name,
        config=config_key,
        title=raw["title"],
        seed=int(overrides["seed"]),
        time_limit_s=float(time_limit_s if time_limit_s is not None else raw["time_limit_s"]),
        ground_friction=float(ground["friction"]),
        robot_start=(start[0], start[1], start[2]),
        objects=_by_id(raw["objects"], overrides.get("objects", {}), "object"),
        terrain=_by_id(raw["terrain"], overrides.get("terrain", {}), "terrain patch"),
        checkpoints=copy.deepcopy(raw["checkpoints"]),
        assists={k: float(v) for k, v in raw.get("assists", {}).items()},
        digest=document_digest(raw),
    )
