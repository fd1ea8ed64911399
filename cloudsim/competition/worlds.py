"""The simulator's worlds and run configurations, as drcsim ships them (no physics loaded)."""

from __future__ import annotations

from functools import cache

from drcsim.worlds import WorldSummary as World
from drcsim.worlds import world_summaries

from cloudsim.errors import InvalidInput

__all__ = ["World", "check_world", "worlds"]


@cache
def worlds() -> dict[str, World]:
    """Return every world the bundled simulator has, by name."""
    return world_summaries()


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
