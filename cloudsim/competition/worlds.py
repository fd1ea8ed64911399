"""The simulator's worlds and run configurations, read from its data files (no pybullet)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from cloudsim.errors import InvalidInput

WORLDS_DIR = Path(__file__).resolve().parents[2] / "simulator" / "drcsim" / "worlds"


@dataclass(frozen=True)
class World:
    """A task world: its title, run configurations and checkpoint names."""

    name: str
    title: str
    configs: tuple[int, ...]
    checkpoints: tuple[str, ...]


@cache
def worlds() -> dict[str, World]:
    """Return every world the bundled simulator has, by name."""
    found: dict[str, World] = {}
    for path in sorted(WORLDS_DIR.glob("*.json")):
        data = json.loads(path.read_text())
        found[data["name"]] = World(
            name=data["name"],
            title=data.get("title", data["name"]),
            configs=tuple(sorted(int(c) for c in data["configs"])),
            checkpoints=tuple(c["name"] for c in data["checkpoints"]),
        )
    return found


def check_world(name: str, config: int) -> World:
    """Return the world, or raise InvalidInput naming the valid worlds or configurations."""
    known = worlds()
    world = known.get(name)
    if world is None:
        raise InvalidInput(f"unknown world {name!r}; choose one of {', '.join(known)}")
    if config not in world.configs:
        choices = ", ".join(map(str, world.configs))
        raise InvalidInput(f"{name} has no run configuration {config}; choose one of {choices}")
    return world
