"""World definitions: each task world is a JSON file with its run configurations as data."""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from importlib import resources
from typing import Any

from drcsim.errors import WorldError

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


def _load_raw(name: str) -> dict[str, Any]:
    if name not in WORLD_NAMES:
        raise WorldError(f"unknown world {name!r} (known: {', '.join(WORLD_NAMES)})")
    text = resources.files(__package__).joinpath(f"{name}.json").read_text()
    data: dict[str, Any] = json.loads(text)
    return data


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
        raw = _load_raw(name)
        found[name] = WorldSummary(
            name=name,
            title=raw.get("title", name),
            configs=tuple(sorted(int(c) for c in raw["configs"])),
            checkpoints=tuple(c["name"] for c in raw["checkpoints"]),
        )
    return found


def _by_id(items: list[dict[str, Any]], overrides: dict[str, dict[str, Any]], kind: str) -> dict:
    resolved = {item["id"]: copy.deepcopy(item) for item in items}
    for item_id, override in overrides.items():
        if item_id not in resolved:
            raise WorldError(f"configuration overrides unknown {kind} {item_id!r}")
        resolved[item_id].update(override)
    return resolved


def load_world(name: str, config: str | int, time_limit_s: float | None = None) -> WorldSpec:
    """Return world `name` in run configuration `config` (1..5)."""
    raw = _load_raw(name)
    config_key = str(config)
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
    )
